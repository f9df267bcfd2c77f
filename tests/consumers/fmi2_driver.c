/*
 * Drives an FMU's FMI 2.0 wrapper with no importer in between, through the
 * calls an importer may get wrong: a wrong GUID, values that are not
 * finite or that setup refuses, value references and sizes out of range,
 * steps that cannot be taken, calls out of order (FMI 2.0's state table,
 * the error state a refused initialization leaves). Built with the FMU's
 * sources under AddressSanitizer and UBSan by tests/test_fmu.py, which
 * reads the lines: "<what> <status>" per call, "log <status> <message>"
 * per logged message, and checks them.
 *
 * argv[1]: the GUID; argv[2]: the value reference of the first runtime
 * parameter (whose start value setup accepts and -1 it refuses); argv[3]:
 * the number of states; argv[4]: the value reference of u1 (1e308 there
 * makes derivatives that are not finite).
 */
#include "fmi2Functions.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>

static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status,
                   fmi2String category, fmi2String message, ...)
{
    va_list args;
    (void)env;
    (void)name;
    (void)category;
    printf("log %d ", (int)status);
    va_start(args, message);
    vprintf(message, args);
    va_end(args);
    printf("\n");
}

static void said(const char *what, fmi2Status status)
{
    printf("%s %d\n", what, (int)status);
}

static void co_simulation(const fmi2CallbackFunctions *cb, const char *guid, fmi2ValueReference p0)
{
    const fmi2ValueReference nowhere = 100000;
    const double nan = NAN, minus_one = -1.0;
    double value = 0.0, start = 0.0;
    const fmi2String unknown[1] = {"logAll"};
    fmi2Component c = fmi2Instantiate("cs", fmi2CoSimulation, "{not-this-one}", "", cb, 0, 0);
    said("wrong_guid", c == NULL ? fmi2Error : fmi2OK); /* refused: no instance */
    c = fmi2Instantiate("cs", fmi2CoSimulation, guid, "", cb, 0, 0);
    said("step_before_initialization", fmi2DoStep(c, 0.0, 0.1, 1));
    said("start_nan", fmi2SetupExperiment(c, 1, 1e-10, NAN, 0, 0.0));
    said("setup_experiment", fmi2SetupExperiment(c, 1, 1e-10, 0.0, 0, 0.0));
    said("enter_initialization", fmi2EnterInitializationMode(c));
    said("get_start", fmi2GetReal(c, &p0, 1, &start));
    said("set_nan", fmi2SetReal(c, &p0, 1, &nan)); /* setup checks it on exit */
    said("set_nowhere", fmi2SetReal(c, &nowhere, 1, &minus_one));
    {
        const fmi2ValueReference twice[2] = {p0, p0};
        const double values[2] = {1.0, 2.0};
        said("set_twice", fmi2SetReal(c, twice, 2, values));
    }
    said("exit_refused", fmi2ExitInitializationMode(c)); /* now in the error state */
    said("set_in_error", fmi2SetReal(c, &p0, 1, &start));
    said("step_in_error", fmi2DoStep(c, 0.0, 0.1, 1));
    said("reset", fmi2Reset(c)); /* the start values again */
    said("setup_again", fmi2SetupExperiment(c, 1, 1e-10, 0.0, 0, 0.0));
    said("enter_again", fmi2EnterInitializationMode(c));
    said("exit_initialization", fmi2ExitInitializationMode(c));
    said("set_refused", fmi2SetReal(c, &p0, 1, &minus_one));
    said("get_after", fmi2GetReal(c, &p0, 1, &value));
    said("kept", value == start ? fmi2OK : fmi2Error);
    said("get_nowhere", fmi2GetReal(c, &nowhere, 1, &value));
    said("unknown_category", fmi2SetDebugLogging(c, 1, 1, unknown));
    said("step", fmi2DoStep(c, 0.0, 0.1, 1));
    said("step_nan", fmi2DoStep(c, 0.1, NAN, 1));
    said("step_backwards", fmi2DoStep(c, 0.1, -1.0, 1));
    said("last_time", fmi2GetRealStatus(c, fmi2LastSuccessfulTime, &value));
    said("at_0.1", value == 0.1 ? fmi2OK : fmi2Error);
    said("other_status", fmi2GetRealStatus(c, fmi2Terminated, &value));
    said("terminate", fmi2Terminate(c));
    said("step_after_terminate", fmi2DoStep(c, 0.1, 0.1, 1));
    fmi2FreeInstance(c);
}

static void model_exchange(const fmi2CallbackFunctions *cb, const char *guid,
                           fmi2ValueReference p0, size_t nx, size_t u1)
{
    double *x = (double *)calloc(nx + 1, sizeof(double));
    double *dx = (double *)calloc(nx + 1, sizeof(double));
    const double nan = NAN;
    fmi2EventInfo info;
    size_t i;
    fmi2Component c = fmi2Instantiate("me", fmi2ModelExchange, guid, "", cb, 0, 0);
    said("continuous_time_before_initialization", fmi2EnterContinuousTimeMode(c));
    said("derivatives_before_initialization", fmi2GetDerivatives(c, dx, nx));
    said("enter_initialization", fmi2EnterInitializationMode(c));
    said("set_nan", fmi2SetReal(c, &p0, 1, &nan));
    said("exit_refused", fmi2ExitInitializationMode(c)); /* now in the error state */
    said("continuous_time_in_error", fmi2EnterContinuousTimeMode(c));
    said("states_in_error", fmi2SetContinuousStates(c, x, nx));
    said("reset", fmi2Reset(c));
    said("enter_initialization", fmi2EnterInitializationMode(c));
    said("exit_initialization", fmi2ExitInitializationMode(c));
    said("new_discrete_states", fmi2NewDiscreteStates(c, &info));
    said("continuous_time", fmi2EnterContinuousTimeMode(c));
    said("states_too_many", fmi2GetContinuousStates(c, x, nx + 1));
    said("states", fmi2GetContinuousStates(c, x, nx));
    said("set_states_too_few", fmi2SetContinuousStates(c, x, nx - 1));
    said("derivatives_too_many", fmi2GetDerivatives(c, dx, nx + 1));
    for (i = 0; i < nx; ++i) x[i] = NAN;
    said("set_nan_states", fmi2SetContinuousStates(c, x, nx));
    said("derivatives_of_nan", fmi2GetDerivatives(c, dx, nx));
    said("time_nan", fmi2SetTime(c, NAN));
    said("time_minus_inf", fmi2SetTime(c, -INFINITY));
    said("time", fmi2SetTime(c, 0.5));
    said("states_again", fmi2GetContinuousStates(c, x, nx));
    x[u1] = 1e308;
    said("set_1e308", fmi2SetContinuousStates(c, x, nx));
    said("derivatives_of_1e308", fmi2GetDerivatives(c, dx, nx));
    said("fmu_state", fmi2GetFMUstate(c, NULL));
    said("reset", fmi2Reset(c));
    fmi2FreeInstance(c);
    free(x);
    free(dx);
}

int main(int argc, char **argv)
{
    fmi2CallbackFunctions cb = {logger, calloc, free, NULL, NULL};
    if (argc != 5) {
        fprintf(stderr, "usage: fmi2_driver GUID VR_OF_FIRST_PARAMETER NX VR_OF_U1\n");
        return 2;
    }
    co_simulation(&cb, argv[1], (fmi2ValueReference)strtoul(argv[2], NULL, 10));
    model_exchange(&cb, argv[1], (fmi2ValueReference)strtoul(argv[2], NULL, 10),
                   (size_t)strtoul(argv[3], NULL, 10), (size_t)strtoul(argv[4], NULL, 10));
    return 0;
}

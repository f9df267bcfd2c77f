/*
 * Embedding a reaction-wheel cluster in a plain C99 program: no Python, no
 * gyrogen, only rw4_pyramid.{h,c} and rw4_pyramid_ode.{h,c} from
 * generated/rw4_pyramid/ (or the library `gyrogen generate rw4_pyramid
 * --lib` builds from them).
 *
 * Four wheels in a pyramid on an 800 kg carrier, each held by its speed
 * controller at a commanded rate relative to the carrier (w_ref_1..4 are
 * the scene's runtime parameters), the motor torques clamped to 0.2 N m:
 * wheels 1 to 3 start 10 rad/s from their commands, so their motors start
 * saturated. 10 s of the generated fixed-step RK4 (dt = 1e-3 s). The
 * program prints the final state, one "name value" per line in the
 * header's state order, the angular momentum about the mass center in N
 * (the generated output function; every motor torque is internal, so it
 * is conserved), its norm, and each motor's power.
 *
 * Initial state (the scene's [simulate]): angles zero;
 *   u1 = 0.01, u2 = 0.02, u3 = -0.01 rad/s (carrier rates, A components),
 *   w1..w4 = 90, -40, 60, 30 rad/s (the wheels' absolute rates about g_k).
 */
#include "rw4_pyramid.h"
#include "rw4_pyramid_ode.h"

#include <math.h>
#include <stdio.h>

#define T_END 10.0
#define DT 1e-3
#define STEPS 10000 /* T_END / DT */

static const char *const state_names[RW4_PYRAMID_NX] = {
    "q1", "q2", "q3", "u1", "u2", "u3", "w1", "w2", "w3", "w4",
};

int main(void)
{
    /* w_ref_1..w_ref_4 (rad/s), in the header's order. */
    const double p[RW4_PYRAMID_NP] = {100.0, -50.0, 80.0, 30.0};
    double c[RW4_PYRAMID_NC];
    double x[RW4_PYRAMID_NX] = {0.0, 0.0, 0.0, 0.01, 0.02, -0.01, 90.0, -40.0, 60.0, 30.0};
    double h0[3], h[3], power[4];
    rw4_pyramid_stats stats;
    int code, k;

    code = rw4_pyramid_setup(p, c);
    if (code != RW4_PYRAMID_OK) {
        fprintf(stderr, "rw4_pyramid_setup failed (code %d)\n", code);
        return 1;
    }
    rw4_pyramid_angular_momentum(0.0, x, c, h0);
    code = rw4_pyramid_rk4(0.0, STEPS * DT, STEPS, x, c, &stats);
    if (code != RW4_PYRAMID_ODE_OK) {
        fprintf(stderr, "rw4_pyramid_rk4 failed (code %d) at t = %g\n", code, stats.t);
        return 1;
    }
    for (k = 0; k < RW4_PYRAMID_NX; ++k) printf("%s %.17g\n", state_names[k], x[k]);
    rw4_pyramid_angular_momentum(T_END, x, c, h);
    printf("H_n1 %.17g\nH_n2 %.17g\nH_n3 %.17g\n", h[0], h[1], h[2]);
    printf("H_norm %.17g\n", sqrt(h[0] * h[0] + h[1] * h[1] + h[2] * h[2]));
    printf("H_drift %.17g\n", sqrt((h[0] - h0[0]) * (h[0] - h0[0]) + (h[1] - h0[1]) * (h[1] - h0[1])
                                   + (h[2] - h0[2]) * (h[2] - h0[2])));
    rw4_pyramid_power(T_END, x, c, power);
    for (k = 0; k < 4; ++k) printf("P%d %.17g\n", k + 1, power[k]);
    return 0;
}

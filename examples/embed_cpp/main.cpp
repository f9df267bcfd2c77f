// Embedding the generated C in a C++17 program: the header's extern "C"
// guards let C++ call the C library directly (examples/CMakeLists.txt links
// gyrostat::gyrostat from the installed CMake package). Sets up the same gyrostat as the C and Fortran
// examples, evaluates the right-hand side once at their initial state and
// prints dxdt, one "name value" per line in the header's state order.
#include "gyrostat.h"

#include <array>
#include <cstddef>
#include <cstdio>

namespace {

constexpr std::array<const char *, GYROSTAT_NX> kStateNames = {
    "q1", "q2", "q3", "q4", "q5", "q6", "q7", "u1", "u2", "u3", "u4", "u5", "u6", "u7"};

}  // namespace

int main()
{
    // m_a m_b I11 I22 I33 I13 I J l1 l3 g T, in the header's order and units.
    const std::array<double, GYROSTAT_NP> p = {500.0, 10.0, 100.0, 80.0, 120.0, 5.0,
                                               0.05,  0.1,  0.2,   -0.1, 0.0,   0.01};
    std::array<double, GYROSTAT_NC> c{};
    std::array<double, GYROSTAT_NX> x{};  // angles and translation zero
    std::array<double, GYROSTAT_NX> dxdt{};

    const int code = gyrostat_setup(p.data(), c.data());
    if (code != GYROSTAT_OK) {
        std::fprintf(stderr, "gyrostat_setup failed with code %d: %s\n", code,
                     gyrostat_strerror(code));
        return 1;
    }
    x[7] = 0.01;    // u1
    x[8] = 0.5;     // u2
    x[9] = -0.02;   // u3
    x[10] = 100.0;  // u4
    gyrostat_rhs(0.0, x.data(), c.data(), dxdt.data());
    for (std::size_t i = 0; i < dxdt.size(); ++i) {
        std::printf("d%s %.17g\n", kStateNames[i], dxdt[i]);
    }
    return 0;
}

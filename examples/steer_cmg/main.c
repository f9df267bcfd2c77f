/*
 * A closed loop in plain C99 around generated code: the four-CMG pyramid
 * (cmg4_pyramid.{h,c} and cmg4_pyramid_ode.{h,c} from generated/cmg4_pyramid/,
 * or the library `gyrogen generate cmg4_pyramid --lib` builds from them)
 * slewed by a singularity-robust steering law.
 *
 * Every PERIOD seconds the controller reads the state and
 *   - computes the attitude error of A from the target (3-1-2 angles q1..q3
 *     of A in N: about n3, then a1', then a2), e = vee(C^T - C) / 2 of the
 *     error rotation C = R_target^T R, and the demanded torque on the carrier
 *     tau = -KP e - KD w_A (A components);
 *   - forms A_hat (3 x 4): column k = g_g_k x g_s_k(gam_k), the direction a
 *     unit gimbal rate of CMG k turns its unit spin momentum; the torque on
 *     the carrier is -H_W A_hat gam_dot;
 *   - steers with the singularity-robust inverse
 *       gam_dot = -(1 / H_W) A_hat^T (A_hat A_hat^T + lambda I)^-1 tau,
 *       lambda = LAMBDA0 exp(-MU det(A_hat A_hat^T)),
 *     which grows as the pyramid nears a singular gimbal set, where det = 0;
 *   - hands gam_dot to the scene's rate servos as the runtime parameters
 *     rate_ref_1..4 (setup, then the generated dop853 over one period).
 *
 * The gimbals start near the singular set (-90, 0, 90, 0) deg, at
 * (-80, 0, 80, 0) deg, the carrier at rest, the wheels at 10,000 rpm; the
 * target is a rotation of 10 deg about n3, then -5 deg about a1', then 5 deg
 * about a2. The program prints, every PRINT_EVERY periods, the time, the
 * pointing error (deg: the angle of C), det(A_hat A_hat^T), lambda and the
 * gimbal angles (deg); then "final_error_deg", "min_det", "max_lambda" and
 * "final_det", one "name value" per line.
 */
#include "cmg4_pyramid.h"
#include "cmg4_pyramid_ode.h"

#include <math.h>
#include <stdio.h>

#define PI 3.14159265358979323846
#define PERIOD 0.05   /* s: the controller's period */
#define T_END 60.0    /* s */
#define PRINT_EVERY 40 /* periods: every 2 s */
#define H_W (1.1e-4 * 1047.1975511965977) /* N m s: each wheel's spin momentum */
#define KP 1.0        /* N m / rad */
#define KD 2.0        /* N m s / rad */
#define LAMBDA0 0.01
#define MU 10.0
#define RATE_MAX 1.0  /* rad/s: the commanded gimbal rates are clamped to it */

/* The scene's axes: gimbal axes g_g (pyramid faces' normals, skew 54.74 deg)
   and the spin axes g_s0 at gimbal angle 0. */
static const double S = 0.8165408118857462, C = 0.5772877120855479;
static const double gimbal_axis[4][3] = {{S, 0, C}, {0, S, C}, {-S, 0, C}, {0, -S, C}};
static const double spin_axis[4][3] = {{0, 1, 0}, {-1, 0, 0}, {0, -1, 0}, {1, 0, 0}};

static void cross(const double a[3], const double b[3], double out[3])
{
    out[0] = a[1] * b[2] - a[2] * b[1];
    out[1] = a[2] * b[0] - a[0] * b[2];
    out[2] = a[0] * b[1] - a[1] * b[0];
}

/* R (A components to N components) of the 3-1-2 angles q. */
static void rotation(const double q[3], double r[3][3])
{
    double c1 = cos(q[0]), s1 = sin(q[0]), c2 = cos(q[1]), s2 = sin(q[1]);
    double c3 = cos(q[2]), s3 = sin(q[2]);
    double r3[3][3] = {{c1, -s1, 0}, {s1, c1, 0}, {0, 0, 1}};
    double r1[3][3] = {{1, 0, 0}, {0, c2, -s2}, {0, s2, c2}};
    double r2[3][3] = {{c3, 0, s3}, {0, 1, 0}, {-s3, 0, c3}};
    double m[3][3];
    int i, j, k;
    for (i = 0; i < 3; ++i)
        for (j = 0; j < 3; ++j)
            for (m[i][j] = 0, k = 0; k < 3; ++k) m[i][j] += r3[i][k] * r1[k][j];
    for (i = 0; i < 3; ++i)
        for (j = 0; j < 3; ++j)
            for (r[i][j] = 0, k = 0; k < 3; ++k) r[i][j] += m[i][k] * r2[k][j];
}

/* The error rotation C = R_target^T R: its axis-angle vector's sine part
   e (A components) and its angle (rad). */
static double attitude_error(const double q[3], const double target[3], double e[3])
{
    double r[3][3], rt[3][3], c[3][3];
    int i, j, k;
    rotation(q, r);
    rotation(target, rt);
    for (i = 0; i < 3; ++i)
        for (j = 0; j < 3; ++j)
            for (c[i][j] = 0, k = 0; k < 3; ++k) c[i][j] += rt[k][i] * r[k][j];
    e[0] = 0.5 * (c[2][1] - c[1][2]);
    e[1] = 0.5 * (c[0][2] - c[2][0]);
    e[2] = 0.5 * (c[1][0] - c[0][1]);
    double cosine = 0.5 * (c[0][0] + c[1][1] + c[2][2] - 1.0);
    return acos(cosine > 1.0 ? 1.0 : cosine < -1.0 ? -1.0 : cosine);
}

/* A_hat's columns at the gimbal angles gam. */
static void torque_directions(const double gam[4], double a[4][3])
{
    int k, i;
    for (k = 0; k < 4; ++k) {
        double t0[3], spin[3];
        cross(gimbal_axis[k], spin_axis[k], t0);
        for (i = 0; i < 3; ++i) spin[i] = cos(gam[k]) * spin_axis[k][i] + sin(gam[k]) * t0[i];
        cross(gimbal_axis[k], spin, a[k]);
    }
}

static double det3(double m[3][3])
{
    return m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
         - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
         + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
}

/* gam_dot = -(1/H_W) A^T (A A^T + lambda I)^-1 tau; returns det(A A^T). */
static double steer(const double gam[4], const double tau[3], double *lambda, double rate[4])
{
    double a[4][3], m[3][3], inv[3][3], y[3];
    int i, j, k;
    torque_directions(gam, a);
    for (i = 0; i < 3; ++i)
        for (j = 0; j < 3; ++j)
            for (m[i][j] = 0, k = 0; k < 4; ++k) m[i][j] += a[k][i] * a[k][j];
    double measure = det3(m);
    *lambda = LAMBDA0 * exp(-MU * measure);
    for (i = 0; i < 3; ++i) m[i][i] += *lambda;
    double d = det3(m);
    for (i = 0; i < 3; ++i)
        for (j = 0; j < 3; ++j) { /* the adjugate's (i, j): the cofactor of (j, i) */
            int r0 = (j + 1) % 3, r1 = (j + 2) % 3, c0 = (i + 1) % 3, c1 = (i + 2) % 3;
            inv[i][j] = (m[r0][c0] * m[r1][c1] - m[r0][c1] * m[r1][c0]) / d;
        }
    for (i = 0; i < 3; ++i)
        for (y[i] = 0, j = 0; j < 3; ++j) y[i] += inv[i][j] * tau[j];
    for (k = 0; k < 4; ++k) {
        double v = -(a[k][0] * y[0] + a[k][1] * y[1] + a[k][2] * y[2]) / H_W;
        rate[k] = v > RATE_MAX ? RATE_MAX : v < -RATE_MAX ? -RATE_MAX : v;
    }
    return measure;
}

int main(void)
{
    const double deg = PI / 180.0;
    const double target[3] = {10.0 * deg, -5.0 * deg, 5.0 * deg};
    const double w = 1047.1975511965977;
    double x[CMG4_PYRAMID_NX] = {0};
    double p[CMG4_PYRAMID_NP], c[CMG4_PYRAMID_NC];
    double min_det = INFINITY, max_lambda = 0.0, measure = 0.0, angle = 0.0;
    cmg4_pyramid_stats stats;
    int n, k, code;
    const int periods = (int)(T_END / PERIOD + 0.5);

    x[3] = -80.0 * deg; /* gam1..gam4 */
    x[5] = 80.0 * deg;
    for (k = 0; k < 4; ++k) x[14 + k] = w; /* w1..w4: 10,000 rpm (the carrier at rest) */
    printf("# t_s error_deg det lambda gam1_deg gam2_deg gam3_deg gam4_deg\n");
    for (n = 0; n <= periods; ++n) {
        double e[3], tau[3], lambda;
        angle = attitude_error(x, target, e);
        for (k = 0; k < 3; ++k) tau[k] = -KP * e[k] - KD * x[7 + k];
        measure = steer(x + 3, tau, &lambda, p);
        if (measure < min_det) min_det = measure;
        if (lambda > max_lambda) max_lambda = lambda;
        if (n % PRINT_EVERY == 0)
            printf("%5.1f %10.3e %9.3e %9.3e %8.2f %8.2f %8.2f %8.2f\n", n * PERIOD,
                   angle / deg, measure, lambda, x[3] / deg, x[4] / deg, x[5] / deg, x[6] / deg);
        if (n == periods) break;
        code = cmg4_pyramid_setup(p, c);
        if (code != CMG4_PYRAMID_OK) {
            fprintf(stderr, "cmg4_pyramid_setup failed (code %d)\n", code);
            return 1;
        }
        code = cmg4_pyramid_dop853(n * PERIOD, (n + 1) * PERIOD, x, c, 1e-10, 1e-10, 0.0,
                                   100000, &stats);
        if (code != CMG4_PYRAMID_ODE_OK) {
            fprintf(stderr, "cmg4_pyramid_dop853 failed (code %d) at t = %g\n", code, stats.t);
            return 1;
        }
    }
    printf("final_error_deg %.6g\nmin_det %.6g\nmax_lambda %.6g\nfinal_det %.6g\n",
           angle / deg, min_det, max_lambda, measure);
    return 0;
}

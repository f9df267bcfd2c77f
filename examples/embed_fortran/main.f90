! Embedding the generated Fortran 2008 module in a plain Fortran program: no
! Python, no gyrogen, only the Fortran library built from generated/gyrostat/
! (its CMake package: examples/CMakeLists.txt links gyrostat::gyrostat_f).
!
! The same run as examples/embed_c/main.c, so the two outputs can be compared
! line by line: a dual-spin-like gyrostat (a 500 kg carrier with a 10 kg
! momentum wheel spinning at 100 rad/s, driven by a 0.01 N m motor) for 10 s
! with the generated fixed-step classical RK4 (dt = 1e-3 s). Prints the final state, one
! "name value" per line in the module's state order, then the angular momentum
! about AB* in N components and its norm (conserved: g = 0, and the motor
! torque is internal).
!
! Initial state: all angles and the translation zero;
!   u1 = 0.01, u2 = 0.5, u3 = -0.02 rad/s (carrier rates, A components),
!   u4 = 100 rad/s (rotor's absolute rate about a2).
program embed_fortran
  use, intrinsic :: iso_c_binding, only: c_double, c_int, c_long, c_loc
  use, intrinsic :: iso_fortran_env, only: error_unit
  use gyrostat_mod, only: gyrostat_setup, gyrostat_strerror, GYROSTAT_NX, GYROSTAT_NP, &
                          GYROSTAT_NC, GYROSTAT_OK
  use gyrostat_ode_mod, only: gyrostat_rk4, gyrostat_ode_strerror, gyrostat_stats, GYROSTAT_ODE_OK
  implicit none

  real(c_double), parameter :: dt = 1.0e-3_c_double
  integer, parameter :: steps = 10000  ! 10 s / dt, an integer so t never accumulates error
  character(len=2), parameter :: state_names(GYROSTAT_NX) = &
    [character(len=2) :: 'q1', 'q2', 'q3', 'q4', 'q5', 'q6', 'q7', &
                         'u1', 'u2', 'u3', 'u4', 'u5', 'u6', 'u7']
  character(len=6), parameter :: h_names(4) = &
    [character(len=6) :: 'H_n1', 'H_n2', 'H_n3', 'H_norm']
  ! m_a m_b I11 I22 I33 I13 I J l1 l3 g T, in the module's order and units.
  real(c_double), parameter :: p(GYROSTAT_NP) = [500.0_c_double, 10.0_c_double, &
    100.0_c_double, 80.0_c_double, 120.0_c_double, 5.0_c_double, 0.05_c_double, &
    0.1_c_double, 0.2_c_double, -0.1_c_double, 0.0_c_double, 0.01_c_double]
  real(c_double) :: c(GYROSTAT_NC), x(GYROSTAT_NX), h(3)
  type(gyrostat_stats), target :: stats  ! passed as c_loc(stats); c_null_ptr when not wanted
  integer(c_int) :: code
  integer :: k

  code = gyrostat_setup(p, c)
  if (code /= GYROSTAT_OK) then
    write (error_unit, '(a, i0, a, a)') 'gyrostat_setup failed (code ', code, '): ', &
      trim(gyrostat_strerror(code))
    error stop 1
  end if

  x = 0.0_c_double
  x(8) = 0.01_c_double    ! u1
  x(9) = 0.5_c_double     ! u2
  x(10) = -0.02_c_double  ! u3
  x(11) = 100.0_c_double  ! u4
  ! The generated classic RK4: `steps` equal steps of dt over [0, 10 s].
  code = gyrostat_rk4(0.0_c_double, steps*dt, int(steps, c_long), x, c, c_loc(stats))
  if (code /= GYROSTAT_ODE_OK) then
    write (error_unit, '(a, i0, a, g0, a, a)') 'gyrostat_rk4 failed with code ', code, ' at t = ', &
      stats%t, ': ', trim(gyrostat_ode_strerror(code))
    error stop 1
  end if

  do k = 1, GYROSTAT_NX
    write (*, '(a, 1x, g0.17)') trim(state_names(k)), x(k)
  end do
  h = angular_momentum_n(p, x)
  do k = 1, 3
    write (*, '(a, 1x, g0.17)') trim(h_names(k)), h(k)
  end do
  write (*, '(a, 1x, g0.17)') trim(h_names(4)), norm2(h)

contains

  ! Angular momentum about AB* in N components (NOTES.md). The module keeps the
  ! lumped inertias inside setup's constants, so they are recomputed here:
  !   mu = m_a m_b / (m_a + m_b)
  !   I~11 = I11 + I + mu l3^2, I~22 = I22 + mu (l1^2 + l3^2),
  !   I~33 = I33 + I + mu l1^2, I~13 = I13 - mu l1 l3
  !   h (A components) = (I~11 u1 + I~13 u3, I~22 u2 + J u4, I~13 u1 + I~33 u3)
  ! and a_i = sum_j C(i,j) n_j (3-1-2 direction cosines), so H_j = sum_i h_i C(i,j).
  function angular_momentum_n(pp, y) result(hn)
    real(c_double), intent(in) :: pp(GYROSTAT_NP), y(GYROSTAT_NX)
    real(c_double) :: hn(3)
    real(c_double) :: mu, t11, t22, t33, t13, ha(3), cm(3, 3)
    real(c_double) :: s1, s2, s3, c1, c2, c3
    mu = pp(1)*pp(2)/(pp(1) + pp(2))
    t11 = pp(3) + pp(7) + mu*pp(10)*pp(10)
    t22 = pp(4) + mu*(pp(9)*pp(9) + pp(10)*pp(10))
    t33 = pp(5) + pp(7) + mu*pp(9)*pp(9)
    t13 = pp(6) - mu*pp(9)*pp(10)
    ha = [t11*y(8) + t13*y(10), t22*y(9) + pp(8)*y(11), t13*y(8) + t33*y(10)]
    s1 = sin(y(1)); s2 = sin(y(2)); s3 = sin(y(3))
    c1 = cos(y(1)); c2 = cos(y(2)); c3 = cos(y(3))
    ! Rows a1, a2, a3; reshape fills column-major, hence the transpose.
    cm = transpose(reshape([c1*c3 - s1*s2*s3, s1*c3 + c1*s2*s3, -c2*s3, &
                            -s1*c2, c1*c2, s2, &
                            s1*s2*c3 + c1*s3, s1*s3 - c1*s2*c3, c2*c3], [3, 3]))
    hn = matmul(ha, cm)
  end function angular_momentum_n

end program embed_fortran

"""Coefficients of the compiled integrators, as the templates render them.

One source for C and Fortran: every value is a double (the correctly rounded
value of the published fraction or decimal) and the templates print it with
`c_double` / `f_double`, which read back exactly. The stage code is rendered
straight-line, one term per nonzero coefficient, so the tables below say
which k_j each stage reads; `terms` drops the zeros. gyrogen.methods names
the methods that use them.

Sources:
- RK4: the classic fourth-order method (Kutta 1901).
- DOPRI5: Dormand & Prince, J. Comp. Appl. Math. 6 (1980); Hairer, Norsett &
  Wanner, Solving ODEs I, Table II.5.2 (the same fractions as Hairer's
  dopri5.f and scipy's RK45).
- DOP853: Hairer's dop853.f (the decimals of its DATA statements, as scipy's
  `_ivp/dop853_coefficients.py` reproduces them): 12 stages, the 8th-order
  weights b, and the 5th- and 3rd-order error weights e5 and e3 = b - bhh.
- RODAS4: Hairer & Wanner, Solving ODEs II, Sec. IV.7, and the RODAS4
  coefficients of Hairer's rodas.f (subroutine ROCOE, METH = 1).
- RADAU5: Radau IIA of order 5 in the transformed form of Hairer & Wanner,
  Solving ODEs II, Sec. IV.8, as Hairer's radau5.f (subroutine RADCOR): the
  nodes, eigenvalues and error weights from their closed forms (evaluated
  at 40 digits, then rounded), T and T^-1 the decimals of its DATA lines.
- Dense output (the interpolant of each accepted step, read only by the
  output grid): DOPRI5's of order 4 (Shampine 1986, the D coefficients of
  Hairer's dopri5.f, CONTD5); DOP853's of order 7 (three more stages and the
  D rows of Hairer's dop853.f, CONTD8, in the decimals of its DATA
  statements); RODAS4's of order 3 (the D2 and D3 rows of rodas.f's ROCOE
  and its CONTRO, as Numerical Recipes' StepperRoss reproduces them);
  RADAU5's collocation polynomial (radau5.f's CONTR5); TAYLOR's series.
- TAYLOR: no tableau; the order of the series from the tolerance, after
  Jorba & Zou, Experiment. Math. 14 (2005), Sec. 3.3.1, as heyoka's
  taylor_order_from_tol: p = max(2, ceil(-ln(rtol)/2 + 1)).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from fractions import Fraction as F

import mpmath

from gyrogen.abi import TAYLOR_MIN_RTOL

Terms = list[tuple[int, float]]


def terms(values: tuple[float, ...]) -> Terms:
    """(j, value) for the nonzero entries: what a rendered sum reads."""
    return [(j, v) for j, v in enumerate(values) if v != 0.0]


def _floats(*values: float | F) -> tuple[float, ...]:
    return tuple(float(v) for v in values)


@dataclass(frozen=True)
class DenseRK:
    """An explicit pair's interpolant in Hairer's form (dopri5.f's CONTD5,
    dop853.f's CONTD8): on a step from x over h to xnew, with theta in [0, 1]
    and theta' = 1 - theta,

        x(t + theta h) = r1 + theta (r2 + theta' (r3 + theta (r4 + theta' (r5 + ...))))

    r1 = x, r2 = xnew - x, r3 = h k_0 - r2, r4 = r2 - h f(t + h, xnew) - r3,
    and r5, r6, ... = h sum_j d[m][j] k_j, the k_j the step's stages, then
    f(t + h, xnew) (the pair's fnew row), then the extra stages: stage s
    evaluates f(t + nodes[s] h, x + h sum_j a[s][j] k_j)."""

    order: int
    nodes: tuple[float, ...]
    a: tuple[tuple[float, ...], ...]
    d: tuple[tuple[float, ...], ...]

    def stage(self, s: int) -> Terms:
        return terms(self.a[s])

    def row(self, m: int) -> Terms:
        return terms(self.d[m])


@dataclass(frozen=True)
class Explicit:
    """An explicit Runge-Kutta method: stage s evaluates k_s = f(t + c_s h,
    x + h sum_j a[s][j] k_j) (row a[s] has s entries), and the step is
    x + h sum_j b_j k_j. An embedded pair adds error weights: the local error
    estimate is h sum_j e_j k_j (and DOP853 a second one with e3)."""

    order: int
    nodes: tuple[float, ...]
    a: tuple[tuple[float, ...], ...]
    b: tuple[float, ...]
    e: tuple[float, ...] = ()
    e3: tuple[float, ...] = ()
    dense: DenseRK | None = None
    """Its interpolant, where it has one (Hairer's form, DenseRK)."""

    @property
    def stages(self) -> int:
        return len(self.nodes)

    @property
    def fsal(self) -> bool:
        """The last stage is evaluated at the new solution (first same as last):
        its k is f(t + h, x_new), the next step's k_0."""
        return self.a[-1] == self.b[: len(self.a[-1])] and self.nodes[-1] == 1.0

    def stage(self, s: int) -> Terms:
        return terms(self.a[s])

    def weights(self) -> Terms:
        return terms(self.b)

    def error(self) -> Terms:
        return terms(self.e)

    def error3(self) -> Terms:
        return terms(self.e3)


@dataclass(frozen=True)
class Rosenbrock:
    """A Rosenbrock method in Hairer & Wanner's form (Solving ODEs II, IV.7.25):
    with E = I/(h gamma) - J, stage s solves

        E k_s = f(t + c_s h, x + sum_j a[s][j] k_j) + sum_j (g[s][j]/h) k_j + h d_s f_t

    The method is stiffly accurate: stage 6 is evaluated at x5 + k5 (the
    embedded solution, order 3) and the step is x5 + k5 + k6, so k6 itself is
    the local error estimate."""

    order: int
    gamma: float
    nodes: tuple[float, ...]
    a: tuple[tuple[float, ...], ...]
    g: tuple[tuple[float, ...], ...]
    d: tuple[float, ...]
    dense: tuple[tuple[float, ...], ...] = ()
    """Its interpolant's two rows (rodas.f's D2j and D3j, over k_1 .. k_5):
    on a step from x to xnew, with theta' = 1 - theta, x(t + theta h) =
    x theta' + theta (xnew + theta' (r3 + theta r4)), r3 and r4 the rows'
    sums of the stages."""

    @property
    def stages(self) -> int:
        return len(self.nodes)

    def stage(self, s: int) -> Terms:
        return terms(self.a[s])

    def dense_row(self, m: int) -> Terms:
        return terms(self.dense[m])

    def feedback(self, s: int) -> Terms:
        return terms(self.g[s])


@dataclass(frozen=True)
class Radau:
    """Radau IIA with three stages (order 5, stiffly accurate, L-stable),
    solved by simplified Newton iterations in Hairer's transformed form: with
    the stage increments Z = (z1, z2, z3) at the nodes (c1, c2, 1) and W =
    T^-1 Z, the Newton matrix of A^-1 splits into a real system with E1 =
    (gamma/h) I - J and a complex one with E2 = ((alpha + i beta)/h) I - J,
    gamma and alpha +- i beta the eigenvalues of A^-1 (A the Radau IIA
    matrix; T its eigenvectors, third row (t31, 1, 0)). The step is x + z3.
    The local error estimate is E1^-1 (f(t, x) + (e1 z1 + e2 z2 + e3 z3)/h),
    gamma/h times Hairer & Wanner's (IV.8.19)."""

    order: int
    nodes: tuple[float, float, float]
    gamma: float
    alpha: float
    beta: float
    t: tuple[tuple[float, float, float], ...]
    ti: tuple[tuple[float, float, float], ...]
    e: tuple[float, float, float]

    @property
    def stages(self) -> int:
        return len(self.nodes)


def _radau5() -> Radau:
    mp = mpmath.mp.clone()
    mp.dps = 40
    sq6, cbrt81, cbrt9 = mp.sqrt(6), mp.cbrt(81), mp.cbrt(9)
    gamma = (6 + cbrt81 - cbrt9) / 30  # the eigenvalues of A, inverted below
    alpha = (12 - cbrt81 + cbrt9) / 60
    beta = (cbrt81 + cbrt9) * mp.sqrt(3) / 60
    norm = alpha**2 + beta**2
    return Radau(
        order=5,
        nodes=(float((4 - sq6) / 10), float((4 + sq6) / 10), 1.0),
        gamma=float(1 / gamma),
        alpha=float(alpha / norm),
        beta=float(beta / norm),
        t=(
            (9.1232394870892942792e-02, -0.14125529502095420843, -3.0029194105147424492e-02),
            (0.24171793270710701896, 0.20412935229379993199, 0.38294211275726193779),
            (0.96604818261509293619, 1.0, 0.0),
        ),
        ti=(
            (4.3255798900631553510, 0.33919925181580986954, 0.54177053993587487119),
            (-4.1787185915519047273, -0.32768282076106238708, 0.47662355450055045196),
            (-0.50287263494578687595, 2.5719269498556054292, -0.59603920482822492497),
        ),
        e=(float(-(13 + 7 * sq6) / 3), float((-13 + 7 * sq6) / 3), float(mp.mpf(-1) / 3)),
    )


RK4 = Explicit(
    order=4,
    nodes=_floats(0, F(1, 2), F(1, 2), 1),
    a=((), _floats(F(1, 2)), _floats(0, F(1, 2)), _floats(0, 0, 1)),
    b=_floats(F(1, 6), F(1, 3), F(1, 3), F(1, 6)),
)

# fmt: off
_DOPRI5_B = (F(35, 384), F(0), F(500, 1113), F(125, 192), F(-2187, 6784), F(11, 84), F(0))
_DOPRI5_BHAT = (
    F(5179, 57600), F(0), F(7571, 16695), F(393, 640), F(-92097, 339200), F(187, 2100), F(1, 40)
)
DOPRI5 = Explicit(
    order=5,
    nodes=_floats(0, F(1, 5), F(3, 10), F(4, 5), F(8, 9), 1, 1),
    a=(
        (),
        _floats(F(1, 5)),
        _floats(F(3, 40), F(9, 40)),
        _floats(F(44, 45), F(-56, 15), F(32, 9)),
        _floats(F(19372, 6561), F(-25360, 2187), F(64448, 6561), F(-212, 729)),
        _floats(F(9017, 3168), F(-355, 33), F(46732, 5247), F(49, 176), F(-5103, 18656)),
        _floats(*_DOPRI5_B[:6]),
    ),
    b=_floats(*_DOPRI5_B),
    e=_floats(*(b - bh for b, bh in zip(_DOPRI5_B, _DOPRI5_BHAT, strict=True))),
    dense=DenseRK(
        order=4,
        nodes=(),
        a=(),
        d=(_floats(F(-12715105075, 11282082432), 0, F(87487479700, 32700410799),
                   F(-10690763975, 1880347072), F(701980252875, 199316789632),
                   F(-1453857185, 822651844), F(69997945, 29380423)),),
    ),
)

_DOP853_B = (
    5.42937341165687622380535766363e-2, 0.0, 0.0, 0.0, 0.0,
    4.45031289275240888144113950566, 1.89151789931450038304281599044,
    -5.8012039600105847814672114227, 3.1116436695781989440891606237e-1,
    -1.52160949662516078556178806805e-1, 2.01365400804030348374776537501e-1,
    4.47106157277725905176885569043e-2,
)
_DOP853_BHH = (
    0.244094488188976377952755905512, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
    0.733846688281611857341361741547, 0.0, 0.0, 0.220588235294117647058823529412e-1,
)
DOP853 = Explicit(
    order=8,
    nodes=(
        0.0,
        0.526001519587677318785587544488e-1,
        0.789002279381515978178381316732e-1,
        0.118350341907227396726757197510,
        0.281649658092772603273242802490,
        0.333333333333333333333333333333,
        0.25,
        0.307692307692307692307692307692,
        0.651282051282051282051282051282,
        0.6,
        0.857142857142857142857142857142,
        1.0,
    ),
    a=(
        (),
        (5.26001519587677318785587544488e-2,),
        (1.97250569845378994544595329183e-2, 5.91751709536136983633785987549e-2),
        (2.95875854768068491816892993775e-2, 0.0, 8.87627564304205475450678981324e-2),
        (2.41365134159266685502369798665e-1, 0.0, -8.84549479328286085344864962717e-1,
         9.24834003261792003115737966543e-1),
        (3.7037037037037037037037037037e-2, 0.0, 0.0, 1.70828608729473871279604482173e-1,
         1.25467687566822425016691814123e-1),
        (3.7109375e-2, 0.0, 0.0, 1.70252211019544039314978060272e-1,
         6.02165389804559606850219397283e-2, -1.7578125e-2),
        (3.70920001185047927108779319836e-2, 0.0, 0.0, 1.70383925712239993810214054705e-1,
         1.07262030446373284651809199168e-1, -1.53194377486244017527936158236e-2,
         8.27378916381402288758473766002e-3),
        (6.24110958716075717114429577812e-1, 0.0, 0.0, -3.36089262944694129406857109825,
         -8.68219346841726006818189891453e-1, 2.75920996994467083049415600797e1,
         2.01540675504778934086186788979e1, -4.34898841810699588477366255144e1),
        (4.77662536438264365890433908527e-1, 0.0, 0.0, -2.48811461997166764192642586468,
         -5.90290826836842996371446475743e-1, 2.12300514481811942347288949897e1,
         1.52792336328824235832596922938e1, -3.32882109689848629194453265587e1,
         -2.03312017085086261358222928593e-2),
        (-9.3714243008598732571704021658e-1, 0.0, 0.0, 5.18637242884406370830023853209,
         1.09143734899672957818500254654, -8.14978701074692612513997267357,
         -1.85200656599969598641566180701e1, 2.27394870993505042818970056734e1,
         2.49360555267965238987089396762, -3.0467644718982195003823669022),
        (2.27331014751653820792359768449, 0.0, 0.0, -1.05344954667372501984066689879e1,
         -2.00087205822486249909675718444, -1.79589318631187989172765950534e1,
         2.79488845294199600508499808837e1, -2.85899827713502369474065508674,
         -8.87285693353062954433549289258, 1.23605671757943030647266201528e1,
         6.43392746015763530355970484046e-1),
    ),
    b=_DOP853_B,
    e=(
        0.1312004499419488073250102996e-1, 0.0, 0.0, 0.0, 0.0,
        -0.1225156446376204440720569753e1, -0.4957589496572501915214079952,
        0.1664377182454986536961530415e1, -0.3503288487499736816886487290,
        0.3341791187130174790297318841, 0.8192320648511571246570742613e-1,
        -0.2235530786388629525884427845e-1,
    ),
    e3=tuple(b - bhh for b, bhh in zip(_DOP853_B, _DOP853_BHH, strict=True)),
    dense=DenseRK(
        order=7,
        # stages 13, 14, 15 (k_0 .. k_11 the step's, k_12 = f(t + h, xnew))
        nodes=(0.1, 0.2, 0.777777777777777777777777777778),
        a=(
            (5.61675022830479523392909219681e-2, 0.0, 0.0, 0.0, 0.0, 0.0,
             2.53500210216624811088794765333e-1, -2.46239037470802489917441475441e-1,
             -1.24191423263816360469010140626e-1, 1.5329179827876569731206322685e-1,
             8.20105229563468988491666602057e-3, 7.56789766054569976138603589584e-3,
             -8.298e-3),
            (3.18346481635021405060768473261e-2, 0.0, 0.0, 0.0, 0.0,
             2.83009096723667755288322961402e-2, 5.35419883074385676223797384372e-2,
             -5.49237485713909884646569340306e-2, 0.0, 0.0,
             -1.08347328697249322858509316994e-4, 3.82571090835658412954920192323e-4,
             -3.40465008687404560802977114492e-4, 1.41312443674632500278074618366e-1),
            (-4.28896301583791923408573538692e-1, 0.0, 0.0, 0.0, 0.0,
             -4.69762141536116384314449447206, 7.68342119606259904184240953878,
             4.06898981839711007970213554331, 3.56727187455281109270669543021e-1,
             0.0, 0.0, 0.0, -1.39902416515901462129418009734e-3,
             2.9475147891527723389556272149, -9.15095847217987001081870187138),
        ),
        d=(
            (-0.84289382761090128651353491142e1, 0.0, 0.0, 0.0, 0.0,
             0.56671495351937776962531783590, -0.30689499459498916912797304727e1,
             0.23846676565120698287728149680e1, 0.21170345824450282767155149946e1,
             -0.87139158377797299206789907490, 0.22404374302607882758541771650e1,
             0.63157877876946881815570249290, -0.88990336451333310820698117400e-1,
             0.18148505520854727256656404962e2, -0.91946323924783554000451984436e1,
             -0.44360363875948939664310572000e1),
            (0.10427508642579134603413151009e2, 0.0, 0.0, 0.0, 0.0,
             0.24228349177525818288430175319e3, 0.16520045171727028198505394887e3,
             -0.37454675472269020279518312152e3, -0.22113666853125306036270938578e2,
             0.77334326684722638389603898808e1, -0.30674084731089398182061213626e2,
             -0.93321305264302278729567221706e1, 0.15697238121770843886131091075e2,
             -0.31139403219565177677282850411e2, -0.93529243588444783865713862664e1,
             0.35816841486394083752465898540e2),
            (0.19985053242002433820987653617e2, 0.0, 0.0, 0.0, 0.0,
             -0.38703730874935176555105901742e3, -0.18917813819516756882830838328e3,
             0.52780815920542364900561016686e3, -0.11573902539959630126141871134e2,
             0.68812326946963000169666922661e1, -0.10006050966910838403183860980e1,
             0.77771377980534432092869265740, -0.27782057523535084065932004339e1,
             -0.60196695231264120758267380846e2, 0.84320405506677161018159903784e2,
             0.11992291136182789328035130030e2),
            (-0.25693933462703749003312586129e2, 0.0, 0.0, 0.0, 0.0,
             -0.15418974869023643374053993627e3, -0.23152937917604549567536039109e3,
             0.35763911791061412378285349910e3, 0.93405324183624310003907691704e2,
             -0.37458323136451633156875139351e2, 0.10409964950896230045147246184e3,
             0.29840293426660503123344363579e2, -0.43533456590011143754432175058e2,
             0.96324553959188282948394950600e2, -0.39177261675615439165231486172e2,
             -0.14972683625798562581422125276e3),
        ),
    ),
)

_RODAS4_A5 = (
    0.1221224509226641e1, 0.6019134481288629e1, 0.1253708332932087e2, -0.6878860361058950
)
RODAS4 = Rosenbrock(
    order=4,
    gamma=0.25,
    nodes=(0.0, 0.386, 0.21, 0.63, 1.0, 1.0),
    a=(
        (),
        (0.1544e1,),
        (0.9466785280815826, 0.2557011698983284),
        (0.3314825187068521e1, 0.2896124015972201e1, 0.9986419139977817),
        _RODAS4_A5,
        (*_RODAS4_A5, 1.0),  # stage 6 at x5 + k5
    ),
    g=(
        (),
        (-0.56688e1,),
        (-0.2430093356833875e1, -0.2063599157091915),
        (-0.1073529058151375, -0.9594562251023355e1, -0.2047028614809616e2),
        (0.7496443313967647e1, -0.1024680431464352e2, -0.3399990352819905e2,
         0.1170890893206160e2),
        (0.8083246795921522e1, -0.7981132988064893e1, -0.3152159432874371e2,
         0.1631930543123136e2, -0.6058818238834054e1),
    ),
    d=(0.25, -0.1043, 0.1035, -0.3620000000000023e-1, 0.0, 0.0),
    dense=(
        (0.1012623508344586e2, -0.7487995877610167e1, -0.3480091861555747e2,
         -0.7992771707568823e1, 0.1025137723295662e1),
        (-0.6762803392801253, 0.6087714651680015e1, 0.1643084320892478e2,
         0.2476722511418386e2, -0.6594389125716872e1),
    ),
)

# fmt: on

RADAU5 = _radau5()


@dataclass(frozen=True)
class Series:
    """A Taylor series method: no stages; the order of the series comes from
    the tolerance (Jorba & Zou's p = ceil(-ln(tol)/2 + 1), at least min_order)
    and is at most `order`, the one an rtol just above abi.TAYLOR_MIN_RTOL asks for."""

    order: int
    min_order: int = 2

    def thresholds(self) -> tuple[float, ...]:
        """e^(-2 (q - 1)) for q = min_order .. order - 1: the order is
        min_order plus the number of these above rtol."""
        return tuple(math.exp(-2.0 * (q - 1)) for q in range(self.min_order, self.order))


TAYLOR = Series(order=math.ceil(-math.log(TAYLOR_MIN_RTOL) / 2 + 1))
"""rtol > abi.TAYLOR_MIN_RTOL = DBL_EPSILON: order 20 at most."""

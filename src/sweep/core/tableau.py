"""Butcher tableau of DOP853 (Dormand & Prince 8(5,3)) with its 7th-order dense output.

Values are the published constants of Hairer, Norsett & Wanner, *Solving Ordinary Differential
Equations I*, 2nd ed. (Springer 1993), section II.10, as distributed with their code dop853.f.
They are data, not code: `tests/test_tableau.py` checks the order (8 for the step, 7 for the
dense output) on problems with known solutions, so a mistyped digit cannot go unnoticed.

Layout: stages 0..11 are the RK stages; stage 12 is f(t+h, y_new) (reused as stage 0 of the next
step); stages 13..15 are evaluated only when dense output is needed (event location, sampling).
"""
import numpy as np

N_STAGES = 12
N_STAGES_EXTENDED = 16
INTERPOLATOR_POWER = 7

C = np.array([
    0.0,
    0.05260015195876773,
    0.0789002279381516,
    0.1183503419072274,
    0.2816496580927726,
    0.3333333333333333,
    0.25,
    0.3076923076923077,
    0.6512820512820513,
    0.6,
    0.8571428571428571,
    1.0,
    1.0,
    0.1,
    0.2,
    0.7777777777777778,
])

A = np.array([
    [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    [0.05260015195876773, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    [0.0197250569845379, 0.0591751709536137, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    [0.02958758547680685, 0.0, 0.08876275643042054, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    [0.2413651341592667, 0.0, -0.8845494793282861, 0.924834003261792, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    [0.037037037037037035, 0.0, 0.0, 0.17082860872947386, 0.12546768756682242, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    [0.037109375, 0.0, 0.0, 0.17025221101954405, 0.06021653898045596, -0.017578125, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    [0.03709200011850479, 0.0, 0.0, 0.17038392571223998, 0.10726203044637328, -0.015319437748624402, 0.008273789163814023, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    [0.6241109587160757, 0.0, 0.0, -3.3608926294469414, -0.868219346841726, 27.59209969944671, 20.154067550477894, -43.48988418106996, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    [0.47766253643826434, 0.0, 0.0, -2.4881146199716677, -0.590290826836843, 21.230051448181193, 15.279233632882423, -33.28821096898486, -0.020331201708508627, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    [-0.9371424300859873, 0.0, 0.0, 5.186372428844064, 1.0914373489967295, -8.149787010746927, -18.52006565999696, 22.739487099350505, 2.4936055526796523, -3.0467644718982196, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    [2.273310147516538, 0.0, 0.0, -10.53449546673725, -2.0008720582248625, -17.9589318631188, 27.94888452941996, -2.8589982771350235, -8.87285693353063, 12.360567175794303, 0.6433927460157636, 0.0, 0.0, 0.0, 0.0, 0.0],
    [0.054293734116568765, 0.0, 0.0, 0.0, 0.0, 4.450312892752409, 1.8915178993145003, -5.801203960010585, 0.3111643669578199, -0.1521609496625161, 0.20136540080403034, 0.04471061572777259, 0.0, 0.0, 0.0, 0.0],
    [0.056167502283047954, 0.0, 0.0, 0.0, 0.0, 0.0, 0.25350021021662483, -0.2462390374708025, -0.12419142326381637, 0.15329179827876568, 0.00820105229563469, 0.007567897660545699, -0.008298, 0.0, 0.0, 0.0],
    [0.03183464816350214, 0.0, 0.0, 0.0, 0.0, 0.028300909672366776, 0.053541988307438566, -0.05492374857139099, 0.0, 0.0, -0.00010834732869724932, 0.0003825710908356584, -0.00034046500868740456, 0.1413124436746325, 0.0, 0.0],
    [-0.42889630158379194, 0.0, 0.0, 0.0, 0.0, -4.697621415361164, 7.683421196062599, 4.06898981839711, 0.3567271874552811, 0.0, 0.0, 0.0, -0.0013990241651590145, 2.9475147891527724, -9.15095847217987, 0.0],
])

B = np.array([
    0.054293734116568765,
    0.0,
    0.0,
    0.0,
    0.0,
    4.450312892752409,
    1.8915178993145003,
    -5.801203960010585,
    0.3111643669578199,
    -0.1521609496625161,
    0.20136540080403034,
    0.04471061572777259,
])

E3 = np.array([
    -0.18980075407240762,
    0.0,
    0.0,
    0.0,
    0.0,
    4.450312892752409,
    1.8915178993145003,
    -5.801203960010585,
    -0.4226823213237919,
    -0.1521609496625161,
    0.20136540080403034,
    0.02265179219836082,
    0.0,
])

E5 = np.array([
    0.01312004499419488,
    0.0,
    0.0,
    0.0,
    0.0,
    -1.2251564463762044,
    -0.4957589496572502,
    1.6643771824549864,
    -0.35032884874997366,
    0.3341791187130175,
    0.08192320648511571,
    -0.022355307863886294,
    0.0,
])

D = np.array([
    [-8.428938276109013, 0.0, 0.0, 0.0, 0.0, 0.5667149535193777, -3.0689499459498917, 2.38466765651207, 2.117034582445028, -0.871391583777973, 2.2404374302607883, 0.6315787787694688, -0.08899033645133331, 18.148505520854727, -9.194632392478356, -4.436036387594894],
    [10.427508642579134, 0.0, 0.0, 0.0, 0.0, 242.28349177525817, 165.20045171727028, -374.5467547226902, -22.113666853125306, 7.733432668472264, -30.674084731089398, -9.332130526430229, 15.697238121770845, -31.139403219565178, -9.35292435884448, 35.81684148639408],
    [19.985053242002433, 0.0, 0.0, 0.0, 0.0, -387.0373087493518, -189.17813819516758, 527.8081592054236, -11.57390253995963, 6.8812326946963, -1.0006050966910838, 0.7777137798053443, -2.778205752353508, -60.19669523126412, 84.32040550667716, 11.99229113618279],
    [-25.69393346270375, 0.0, 0.0, 0.0, 0.0, -154.18974869023643, -231.5293791760455, 357.6391179106141, 93.40532418362432, -37.45832313645163, 104.0996495089623, 29.8402934266605, -43.53345659001114, 96.32455395918828, -39.17726167561544, -149.72683625798564],
])


# The stages each combination reads (stages 1-4 of B, E3, E5 and D are zero; a third of A's lower
# triangle too): the generated sums (dop853_sums.py) read the nonzero ones only, in increasing
# stage order.
B_COLS = np.nonzero(B)[0]
E_COLS = np.nonzero((E3 != 0.0) | (E5 != 0.0))[0]
D_COLS = np.nonzero(np.any(D != 0.0, axis=0))[0]

SUMS_MODULE = "dop853_sums.py"


def _sum(coefs, cols) -> str:
    """0.0 + c_j * K[j, i] + ... over the nonzero coefficients, in increasing stage order: the
    floating-point sum that a loop accumulating from 0.0 forms, term by term."""
    return " + ".join(["0.0"] + [f"{float(coefs[j])!r} * K[{j}, i]" for j in cols if coefs[j] != 0.0])


def _stages_source(name: str, first: int, last: int, what: str) -> list[str]:
    out = ["", "", '@kernel(inline="always")', f"def {name}(rhs, t, y, h, sys, K):",
           f'    """{what}: stage s at t + c_s h from y + h sum_j a_sj K[j] (K[0]: f at t), into K[s]."""',
           "    n, wk = sys.n, sys.wk", "    ytmp, aux = wk[W_YTMP], wk[W_AUXTMP]"]
    for s in range(first, last):
        out += ["    for i in range(n):",
                f"        ytmp[i] = y[i] + h * ({_sum(A[s], range(s))})",
                f"    rhs(t + {float(C[s])!r} * h, ytmp, sys, K[{s}], aux)"]
    return out


def sums_source() -> str:
    """The source of dop853_sums.py: DOP853's stage, increment, error and dense-output sums as
    straight-line code with the tableau's coefficients as literals (`python
    src/sweep/core/tableau.py` writes it; tests/test_tableau.py checks that the file is this text).

    One loop over the state per stage, not one per tableau entry (~60 per step, each with its
    set-up): a step's sums cost 178 ns against 365 ns (rk_step with a trivial right-hand side,
    n = 14). Each component's terms are added from 0.0 in increasing stage order, as a loop over
    the tableau adds them."""
    out = ['"""DOP853\'s sums as straight-line code, GENERATED from tableau.py: do not edit; edit the',
           "generator (tableau.sums_source) and rerun it: `python src/sweep/core/tableau.py`.", "",
           "Each sum adds its terms from 0.0 in increasing stage order over the tableau's nonzero",
           'coefficients (dop853.py calls these kernels)."""',
           "from .jit import kernel",
           "from .layout import W_AUXTMP, W_YTMP"]
    out += _stages_source("main_stages", 1, N_STAGES, "Stages 1..11 of a step")
    out += _stages_source("dense_stages", N_STAGES + 1, N_STAGES_EXTENDED,
                          "Stages 13..15 (the dense output's; K[12] = f(t + h, y_new))")
    out += ["", "", "@kernel", "def increment(K, h, y, y_new, delta, n):",
            '    """The step\'s increment delta = h sum_j b_j K[j] (before rounding) and y_new = y + delta."""',
            "    for i in range(n):", f"        delta[i] = h * ({_sum(B, B_COLS)})", "        y_new[i] = y[i] + delta[i]"]
    out += ["", "", "@kernel", "def error_sums(K, i):",
            '    """Component i of the 5th- and 3rd-order error estimates over h: (sum_j e5_j K[j, i], sum_j e3_j K[j, i])."""',
            f"    return ({_sum(E5, E_COLS)},", f"            {_sum(E3, E_COLS)})"]
    out += ["", "", "@kernel", "def dense_rows(K, h, F, n):",
            '    """Rows 3..6 of the dense-output coefficients: F[3 + r] = h sum_j d_rj K[j]."""',
            "    for i in range(n):"]
    out += [f"        F[{3 + r}, i] = h * ({_sum(D[r], D_COLS)})" for r in range(D.shape[0])]
    return "\n".join(out) + "\n"


if __name__ == "__main__":
    from pathlib import Path
    target = Path(__file__).with_name(SUMS_MODULE)
    target.write_text(sums_source())
    print(f"written: {target}")

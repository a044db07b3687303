"""Independent numpy/scipy reference for the MSD double-flap mechanism (seed 000_0e5ea70f9886b82a).

Ground truth for tests; it uses none of the report's velocity/acceleration/torque formulas
(except ``torque_document``, which transcribes the report's printed T_m on purpose).
See docs/seeds/flap_msd.md for the model, the branch choice and the list of report mistakes.

Conventions (those of the report)
---------------------------------
* Gauss plane, x right, y up, angles counter-clockwise from +x, radians, SI units.
* Coordinates q = (beta, delta, phi, psi, xi, theta); driver alpha (crank OA).
* delta and theta are *clockwise* flap deflections: chord directions are exp(-i delta)
  (C->F, main flap) and exp(-i theta) (F->L, second flap);
  G - C = i c exp(-i delta),  H - F = i z exp(-i theta).
* Loop closures (complex, each must vanish):
    L1 = a e^{i alpha} + b e^{i beta} - (l - i r) - i c e^{-i delta}
    L2 = d e^{i phi} + p e^{i psi} - (s - i t) - i c e^{-i delta}
    L3 = (i c - c1) e^{-i delta} + g e^{i psi} + h e^{i xi} - i z e^{-i theta}
* Derivatives: ``derivatives`` returns dq/dalpha and d2q/dalpha2; time derivatives are
  qdot = q' alpha_dot, qddot = q'' alpha_dot**2 + q' alpha_ddot.
* Loads (powers as the report's Pi): lift F1 = qdyn S1 Cl_delta delta applied at AC1 along
  +i e^{-i delta} (i.e. F1x = F1 sin(delta), F1y = F1 cos(delta): "up" normal to the chord),
  F2 likewise with theta at AC2; pure moments MAC1*delta_dot + MAC2*theta_dot (MAC = qdyn S c Cm,
  constant, negative); gravity -M G ydot_G1 - m G ydot_G2.
* T_m is the counter-clockwise motor torque at O [N m], from T_m alpha_dot = dT/dt - Pi_loads.
* voltage = R_a T_m / K_m + K_m alpha_dot [V] (steady DC motor, inductance neglected).
"""
import numpy as np
from scipy.optimize import brentq, minimize_scalar

NAMES = ("beta", "delta", "phi", "psi", "xi", "theta")
ALPHA0, ALPHA1 = np.deg2rad(275.0), np.deg2rad(320.0)
# Initial guess at alpha = 275 deg selecting the branch on which theta turns ~60 deg
# (closed-form branch signs (+1, -1, +1), see positions_closed).
GUESS_275 = np.deg2rad([12.75, 0.95, -35.59, 96.00, -13.91, 0.02])
BRANCH = (1, -1, 1)


def params():
    """SI parameters, named as in the report (section 4). G is gravity, g is the E-G length."""
    K = 17.0
    P = dict(K=K, a=3.5 / K, b=9 / K, c=5 / K, l=9 / K, r=6.5 / K, d=9 / K, p=2.25 / K,
             s=7 / K, t=8 / K, g=3 / K, h=17.75 / K, z=4 / K,
             c1=1.0, c2=0.5, M=20.0, m=10.0, G=9.81, rho=1.225, U=240 / 3.6,
             Cl_delta=1.4, Cl_theta=1.3, Cm_delta=-0.3, Cm_theta=-0.3, R_a=2.0, K_m=20.0,
             omega=1.0, alpha0=ALPHA0, alpha1=ALPHA1)
    P["S1"], P["S2"] = 1.5 * P["c1"], 1.5 * P["c2"]
    P["J_M"] = P["M"] * P["c1"] * 3.5 / K   # used as kg m^2 (literally M*c1*a; see doc mistake 17)
    P["J_m"] = P["m"] * P["c2"] * 2.5 / K
    P["qdyn"] = 0.5 * P["rho"] * P["U"] ** 2
    P["F1_delta"] = P["qdyn"] * P["S1"] * P["Cl_delta"]          # N/rad
    P["F2_theta"] = P["qdyn"] * P["S2"] * P["Cl_theta"]          # N/rad
    P["MAC1"] = P["qdyn"] * P["S1"] * P["c1"] * P["Cm_delta"]    # N m
    P["MAC2"] = P["qdyn"] * P["S2"] * P["c2"] * P["Cm_theta"]    # N m
    return P


_P = params()
_Cpt = _P["l"] - 1j * _P["r"]          # C (fixed flap hinge)
_Bpt = _Cpt - (_P["s"] - 1j * _P["t"])  # B (fixed pivot of bar BD)
# Index -1 is alpha; others index q.  A term (coef, idx, sgn) means coef*exp(i*sgn*angle).
_LOOPS = [
    (-_Cpt, [(_P["a"], -1, 1), (_P["b"], 0, 1), (-1j * _P["c"], 1, -1)]),
    (-(_P["s"] - 1j * _P["t"]), [(_P["d"], 2, 1), (_P["p"], 3, 1), (-1j * _P["c"], 1, -1)]),
    (0.0, [(1j * _P["c"] - _P["c1"], 1, -1), (_P["g"], 3, 1), (_P["h"], 4, 1),
           (-1j * _P["z"], 5, -1)]),
]
_c1, _c2 = _P["c1"], _P["c2"]
_POINTS = {
    "O": (0.0, []), "A": (0.0, [(_P["a"], -1, 1)]), "C": (_Cpt, []), "B": (_Bpt, []),
    "G": (_Cpt, [(1j * _P["c"], 1, -1)]),
    "D": (_Bpt, [(_P["d"], 2, 1)]),
    "E": (_Cpt, [(1j * _P["c"], 1, -1), (_P["g"], 3, 1)]),
    "F": (_Cpt, [(_c1, 1, -1)]),
    "H": (_Cpt, [(_c1, 1, -1), (1j * _P["z"], 5, -1)]),
    "L": (_Cpt, [(_c1, 1, -1), (_c2, 5, -1)]),
    "G1": (_Cpt, [(_c1 / 2, 1, -1)]),
    "G2": (_Cpt, [(_c1, 1, -1), (_c2 / 2, 5, -1)]),
    "AC1": (_Cpt, [(_c1 / 4, 1, -1)]),
    "AC2": (_Cpt, [(_c1, 1, -1), (_c2 / 4, 5, -1)]),
}


def _ang(alpha, q, idx):
    return alpha if idx < 0 else q[idx]


def _eval(const, terms, alpha, q, dq=None, ddq=None):
    """Value, d/dalpha and d2/dalpha2 of const + sum coef e^{i sgn angle} (complex)."""
    v, v1, v2 = const, 0j, 0j
    for coef, idx, sg in terms:
        T = coef * np.exp(1j * sg * _ang(alpha, q, idx))
        v = v + T
        if dq is not None:
            w1 = 1.0 if idx < 0 else dq[idx]
            v1 += 1j * sg * T * w1
            if ddq is not None:
                w2 = 0.0 if idx < 0 else ddq[idx]
                v2 += (1j * sg * w2 - w1 ** 2) * T
    return v, v1, v2


def residual(alpha, q):
    """Real 6-vector [Re L1, Im L1, Re L2, Im L2, Re L3, Im L3]."""
    L = np.array([_eval(c0, tm, alpha, q)[0] for c0, tm in _LOOPS])
    return np.concatenate([[x.real, x.imag] for x in L])


def jacobian(alpha, q):
    """Real 6x6 d(residual)/dq (block lower-triangular: loop k rows)."""
    J = np.zeros((6, 6))
    for k, (_, tm) in enumerate(_LOOPS):
        for coef, idx, sg in tm:
            if idx >= 0:
                dT = 1j * sg * coef * np.exp(1j * sg * q[idx])
                J[2 * k, idx] += dT.real
                J[2 * k + 1, idx] += dT.imag
    return J


def loop_dets(alpha, q):
    """2x2 determinants of each loop w.r.t. its own two unknowns ((beta,delta),(phi,psi),(xi,theta)).
    Equal to b c cos(beta+delta), -d p sin(phi-psi), h z cos(theta+xi): the report's det(A) with the
    opposite sign (its velocity matrices A are these Jacobian blocks with the first row negated)."""
    J = jacobian(alpha, q)
    return np.array([np.linalg.det(J[0:2, [0, 1]]), np.linalg.det(J[2:4, [2, 3]]),
                     np.linalg.det(J[4:6, [4, 5]])])


def positions(alpha, guess=None, tol=1e-13, maxit=50):
    """Newton solution q(alpha) of the three loops. guess=None: continuation from GUESS_275
    (alpha = 275 deg) in <= 1 deg steps, i.e. the ~60 deg theta branch."""
    if guess is None:
        n = max(1, int(np.ceil(abs(np.rad2deg(alpha - ALPHA0)))))
        q = np.array(GUESS_275, float)
        for al in np.linspace(ALPHA0, alpha, n + 1):
            q = positions(al, q, tol, maxit)
        return q
    q = np.array(guess, float)
    for _ in range(maxit):
        f = residual(alpha, q)
        if np.max(np.abs(f)) < 1e-15:
            return q
        dx = np.linalg.solve(jacobian(alpha, q), -f)
        q = q + dx
        if np.max(np.abs(dx)) < tol:
            return q
    raise RuntimeError("Newton did not converge at alpha=%g deg" % np.rad2deg(alpha))


def derivatives(alpha, q=None):
    """(q, q', q'') w.r.t. alpha from the exact linear velocity/acceleration systems:
    sum_j i s_j T_j q_j' = -(alpha term)',  sum_j i s_j T_j q_j'' = sum_j q_j'^2 T_j (alpha' = 1)."""
    q = positions(alpha) if q is None else q
    J = jacobian(alpha, q)
    rhs1 = -np.concatenate([[v.real, v.imag] for v in
                            (_eval(c0, [x for x in tm if x[1] < 0], alpha, q, np.zeros(6))[1]
                             for c0, tm in _LOOPS)])
    dq = np.linalg.solve(J, rhs1)
    # second derivative: full d2/dalpha2 of each loop with q''=0, moved to the right-hand side
    rhs2 = -np.concatenate([[v.real, v.imag] for v in
                            (_eval(c0, tm, alpha, q, dq, np.zeros(6))[2] for c0, tm in _LOOPS)])
    ddq = np.linalg.solve(J, rhs2)
    return q, dq, ddq


def points(alpha, q, dq=None, ddq=None):
    """Dict name -> (P, dP/dalpha, d2P/dalpha2) as complex numbers x + i y (derivatives 0 if not given)."""
    return {k: _eval(c0, tm, alpha, q, dq, ddq) for k, (c0, tm) in _POINTS.items()}


def _cc(P1, r1, P2, r2, sg):
    """Angle of X - P1 for X with |X-P1| = r1, |X-P2| = r2 (sign sg picks the intersection)."""
    D = abs(P2 - P1)
    x = (r1 ** 2 + D ** 2 - r2 ** 2) / (2 * r1 * D)
    return None if abs(x) > 1 else np.angle(P2 - P1) + sg * np.arccos(x)


def positions_closed(alpha, branch=BRANCH):
    """Closed-form positions by circle intersections (independent of Newton); branch = signs
    (s1, s2, s3) of the acos in each loop. Returns None where a loop cannot be assembled."""
    return _closed(alpha, branch)[0]


def _closed(alpha, branch):
    P = _P
    margins = [np.nan] * 3
    A = P["a"] * np.exp(1j * alpha)
    dist = abs(A - _Cpt)
    margins[0] = min(P["b"] + P["c"] - dist, dist - abs(P["b"] - P["c"]))
    be = _cc(A, P["b"], _Cpt, P["c"], branch[0])
    if be is None:
        return None, margins
    G = A + P["b"] * np.exp(1j * be)
    de = -np.angle((G - _Cpt) / (1j * P["c"]))
    dist = abs(G - _Bpt)
    margins[1] = min(P["d"] + P["p"] - dist, dist - abs(P["d"] - P["p"]))
    ph = _cc(_Bpt, P["d"], G, P["p"], branch[1])
    if ph is None:
        return None, margins
    D = _Bpt + P["d"] * np.exp(1j * ph)
    ps = np.angle(G - D)
    E, F = G + P["g"] * np.exp(1j * ps), _Cpt + P["c1"] * np.exp(-1j * de)
    dist = abs(E - F)
    margins[2] = min(P["h"] + P["z"] - dist, dist - abs(P["h"] - P["z"]))
    xi = _cc(E, P["h"], F, P["z"], branch[2])
    if xi is None:
        return None, margins
    H = E + P["h"] * np.exp(1j * xi)
    th = -np.angle((H - F) / (1j * P["z"]))
    return np.array([be, de, ph, ps, xi, th]), margins


def assembly_margins(alpha, branch=BRANCH):
    """Distance margins of the 3 loops: min(b+c-|A-C|, |A-C|-|b-c|), same with |G-B| vs d, p and
    |E-F| vs h, z (nan for a loop after one that fails). All > 0 <=> assemblable; a zero <=> that
    loop's Jacobian determinant vanishes (toggle: its two links are aligned)."""
    return np.array(_closed(alpha, branch)[1])


def assembly_limits(branch=BRANCH, step_deg=0.5):
    """[(alpha_low, loop), (alpha_high, loop)]: ends [rad] of the assemblable interval containing
    the stroke; at each end the Jacobian determinant of loop `loop` (1, 2 or 3) vanishes (toggle)."""
    f = lambda al: np.nanmin(assembly_margins(al, branch))
    res = []
    for al, st in ((ALPHA0, -np.deg2rad(step_deg)), (ALPHA1, np.deg2rad(step_deg))):
        while f(al + st) > 0:
            al += st
        lim = brentq(f, al, al + st, xtol=1e-14)
        res.append((lim, int(np.nanargmin(assembly_margins(lim - 1e-9 * np.sign(st), branch))) + 1))
    return res


def torque(alpha, alpha_dot=1.0, alpha_ddot=0.0):
    """Motor torque T_m [N m] (counter-clockwise on crank OA) by the power balance
    T_m*alpha_dot = dT/dt - Pi_loads, with dT/dt = sum m v.a + J w wdot computed from exact
    point velocities/accelerations (no use of the report's T_m/dT/dt formulas)."""
    P = _P
    q, d1, d2 = derivatives(alpha)
    pts = points(alpha, q, d1, d2)
    vel = {k: v[1] * alpha_dot for k, v in pts.items()}
    acc = {k: v[2] * alpha_dot ** 2 + v[1] * alpha_ddot for k, v in pts.items()}
    qd, qdd = d1 * alpha_dot, d2 * alpha_dot ** 2 + d1 * alpha_ddot
    de, th, ded, thd = q[1], q[5], qd[1], qd[5]
    dot = lambda u, v: (np.conj(u) * v).real
    dTdt = (P["M"] * dot(vel["G1"], acc["G1"]) + P["J_M"] * ded * qdd[1]
            + P["m"] * dot(vel["G2"], acc["G2"]) + P["J_m"] * thd * qdd[5])
    F1 = P["F1_delta"] * de * 1j * np.exp(-1j * de)      # (F1 sin d, F1 cos d)
    F2 = P["F2_theta"] * th * 1j * np.exp(-1j * th)
    Pi = (dot(F1, vel["AC1"]) + dot(F2, vel["AC2"]) + P["MAC1"] * ded + P["MAC2"] * thd
          - P["M"] * P["G"] * vel["G1"].imag - P["m"] * P["G"] * vel["G2"].imag)
    return (dTdt - Pi) / alpha_dot


def torque_document(alpha, alpha_dot=1.0, corrected=False):
    """The report's printed T_m (section 3.1), literally: F2 c1 sin(theta-delta) and
    m (c2^2/4)^2; inputs delta', theta' (d/dalpha) and delta_ddot, theta_ddot (alpha_ddot = 0)
    from this module. corrected=True uses cos(theta-delta) and m c2^2/4 (then equals torque)."""
    P = _P
    q, d1, d2 = derivatives(alpha)
    de, th, dp, tp = q[1], q[5], d1[1], d1[5]
    ded2, thd2 = d2[1] * alpha_dot ** 2, d2[5] * alpha_dot ** 2
    M, m, c1, c2, G = P["M"], P["m"], P["c1"], P["c2"], P["G"]
    F1, F2 = P["F1_delta"] * de, P["F2_theta"] * th
    trig = np.cos(th - de) if corrected else np.sin(th - de)
    I2 = m * c2 ** 2 / 4 if corrected else m * (c2 ** 2 / 4) ** 2
    return ((ded2 * (M * c1 ** 2 / 4 + P["J_M"] + m * c1 ** 2) - P["MAC1"] + F1 * c1 / 4
             + F2 * c1 * trig - (M * G * c1 / 2 + m * G * c1) * np.cos(de)) * dp
            + (thd2 * (I2 + P["J_m"]) - P["MAC2"] + F2 * c2 / 4 - m * G * c2 / 2 * np.cos(th)) * tp
            + 0.5 * m * c1 * c2 * ((thd2 * dp + ded2 * tp) * np.cos(th - de)
                                   - dp * tp * np.sin(th - de) * (tp - dp) * alpha_dot ** 2))


def voltage(alpha, alpha_dot=1.0, alpha_ddot=0.0):
    """Input voltage v = R_a T_m / K_m + K_m alpha_dot [V]."""
    P = _P
    return P["R_a"] * torque(alpha, alpha_dot, alpha_ddot) / P["K_m"] + P["K_m"] * alpha_dot


def peak_torque():
    """(alpha_peak [rad], T_max [N m]) over the stroke [275, 320] deg."""
    al = np.linspace(ALPHA0, ALPHA1, 451)
    T = np.array([torque(x) for x in al])
    k = int(np.argmax(T))
    if 0 < k < len(al) - 1:
        r = minimize_scalar(lambda x: -torque(x), bounds=(al[k - 1], al[k + 1]),
                            method="bounded", options={"xatol": 1e-10})
        return r.x, -r.fun
    return al[k], T[k]


if __name__ == "__main__":
    np.set_printoptions(precision=6, suppress=True)
    q0, q1 = positions(ALPHA0, GUESS_275), positions(ALPHA1)
    print("q(275) deg:", np.rad2deg(q0))
    print("q(320) deg:", np.rad2deg(q1))
    print("delta travel %.6f deg, theta travel %.6f deg"
          % tuple(np.rad2deg([q1[1] - q0[1], q1[5] - q0[5]])))
    for deg in (275, 290, 305, 320):
        al = np.deg2rad(deg)
        print("alpha=%d  T_m=%.6f N m  v=%.6f V  T_doc=%.6f" % (deg, torque(al), voltage(al),
                                                                torque_document(al)))
    ap, Tp = peak_torque()
    print("peak T_m = %.6f N m at alpha = %.6f deg" % (Tp, np.rad2deg(ap)))
    for (lim, k) in assembly_limits():
        print("assembly limit (loop %d singular) at alpha = %.6f deg" % (k, np.rad2deg(lim) % 360))

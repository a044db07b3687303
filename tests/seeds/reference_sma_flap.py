"""Independent numpy/scipy reference for the SMA-actuated hinged flap (seed 004_52c3b6aed7b0817f).

Ground truth for tests.  Plain numpy/scipy: it must not import jax or jaxmech.
See docs/seeds/sma_flap.md for the model, the chosen parameters (the document gives none),
and the list of document mistakes.

Conventions
-----------
* Gauss plane of the airfoil section: x aft (leading edge at 0), y up; complex points; SI.
* Bodies: 0 = fixed fore body (wing), 1 = first flap segment, 2 = second segment.
  Hinge j joins body j-1 (ahead) and body j (behind); J_j is its reference position.
* theta_j: rotation of body j *relative to body j-1*, counter-clockwise positive, i.e.
  theta_j > 0 lifts the trailing edge.  theta = 0 is the undeflected (reference) shape.
  Body b's absolute angle is phi_b = theta_1 + ... + theta_b.
* A reference point p of body b is at
      z_b(p) = z_{b-1}(J_b) + exp(i phi_b) (p - J_b),     z_0(p) = p,
  and dz_b(p)/dtheta_j = i (z_b(p) - z_{j-1}(J_j)) for b >= j, else 0.
* Actuators (SMA wire or bias spring) of hinge j join point F (on body j-1) and point A
  (on body j).  Length L = |z(A) - z(F)|.  T is the *tension* (positive pulls A towards F).
    - SMA wire:   T = E A_w (L / L_free - 1),  L_free = L0 (1 + eps)   (strain-driven)
                  T = F_s prescribed                                  (force-driven)
      L0 = wire length at theta = 0, eps = prescribed SMA (transformation) strain, eps < 0
      is a commanded contraction (the document's eta = 1 + eps).  The wire cannot push:
      T = max(T, 0) (slack) - never active at the equilibria reported here.
    - Bias spring: T = F_pre + k (L - L0)  (linear, preload F_pre at theta = 0).
* Equilibrium (virtual work; equivalently the moment balance about each hinge J_j of all
  forces on bodies j, j+1, ...):
      R_j(theta) = dV/dtheta_j = sum_act T dL/dtheta_j + sum_b m_b g d(y_cg,b)/dtheta_j = 0,
  where V is the potential; R_j = -(net CCW moment about J_j on bodies >= j).
  Stable equilibrium: Hessian dR/dtheta positive definite.

The document's fixed point (its Algorithm 1, with the physics corrected - see the doc):
  given theta^k, compute the spring tension that balances hinge j,
      T_need = -(R_j - T_spring dL_spring/dtheta_j) / (dL_spring/dtheta_j),
  turn it into a spring length L0 + (T_need - F_pre)/k (eq. 1.15), and take theta_j^{k+1}
  from the spring's inverse kinematics (eqs. 1.5-1.9, corrected: circle intersection).
  Linearised, theta^{k+1} - theta* = (I - D^-1 H)(theta^k - theta*), D = diag(k_j L'_j^2),
  H the Hessian: for one hinge the rate is 1 - V''/(k L_spring'^2).  It diverges (with
  sign-alternating oscillation) once the total rotational stiffness exceeds twice the
  spring's own, i.e. for any stiff (realistic) wire against a soft bias spring.
"""
import numpy as np
from scipy.optimize import brentq

G = 9.81  # m/s^2


# --------------------------------------------------------------------------- parameters
def wire_area(diameter):
    """Cross-section of a round wire [m^2]."""
    return np.pi * diameter ** 2 / 4


def params(n_hinges=2):
    """Chosen parameter set (SI).  n_hinges = 1: the two segments locked as one rigid flap.

    Section of a 0.40 m chord wind-tunnel wing, 0.30 m span; hinge 1 at 55 % chord,
    hinge 2 at 77.5 % chord, trailing edge at 0.40 m.  NiTi wire 0.381 mm (0.015 in,
    Flexinol-like): E_M = 28 GPa, E_A = 75 GPa, recoverable strain <= 4 %.
    Each hinge carries a short horn: the wire pulls a point directly above the hinge
    (upper side, lifts the trailing edge), the bias spring a point directly below it.
    """
    Aw = wire_area(0.381e-3)
    J = [0.22 + 0j, 0.31 + 0j]
    sma = [dict(hinge=1, F=0.06 + 0.010j, A=0.22 + 0.010j),
           dict(hinge=2, F=0.23 + 0.008j, A=0.31 + 0.008j)]
    spring = [dict(hinge=1, F=0.14 - 0.010j, A=0.22 - 0.010j, k=1000.0, F_pre=5.0),
              dict(hinge=2, F=0.27 - 0.008j, A=0.31 - 0.008j, k=800.0, F_pre=3.0)]
    for s in sma:
        s.update(E_M=28e9, E_A=75e9, area=Aw, L0=abs(s["A"] - s["F"]))
    for s in spring:
        s["L0"] = abs(s["A"] - s["F"])
    mass, cg = [0.06, 0.04], [0.265 + 0j, 0.355 + 0j]
    if n_hinges == 1:
        m = mass[0] + mass[1]
        return dict(n=1, J=J[:1], sma=sma[:1], spring=spring[:1], mass=[m],
                    cg=[(mass[0] * cg[0] + mass[1] * cg[1]) / m], g=G, eps_max=0.04)
    return dict(n=2, J=J, sma=sma, spring=spring, mass=mass, cg=cg, g=G, eps_max=0.04)


# --------------------------------------------------------------------------- kinematics
def _frames(theta, P):
    """Per body b = 0..n: (o_b, rot_b, J_b) with z_b(p) = o_b + rot_b (p - J_b)."""
    theta = np.atleast_1d(np.asarray(theta, float))
    fr = [(0j, 1.0 + 0j, 0j)]
    phi = 0.0
    for b in range(1, P["n"] + 1):
        Jb = P["J"][b - 1]
        o_prev, r_prev, J_prev = fr[-1]
        phi += theta[b - 1]
        fr.append((o_prev + r_prev * (Jb - J_prev), np.exp(1j * phi), Jb))
    return fr


def point(theta, P, b, p, fr=None):
    """Current complex position of reference point p of body b."""
    o, r, Jb = (fr or _frames(theta, P))[b]
    return o + r * (p - Jb)


def hinge(theta, P, j, fr=None):
    """Current position of hinge j (it is fixed on body j-1)."""
    return (fr or _frames(theta, P))[j][0]


def dpoint(theta, P, b, p, j, fr=None):
    """d z_b(p) / d theta_j."""
    if b < j:
        return 0j
    fr = fr or _frames(theta, P)
    return 1j * (point(theta, P, b, p, fr) - hinge(theta, P, j, fr))


def length(theta, P, act, fr=None):
    """Actuator length |z(A) - z(F)| [m]."""
    fr = fr or _frames(theta, P)
    h = act["hinge"]
    return abs(point(theta, P, h, act["A"], fr) - point(theta, P, h - 1, act["F"], fr))


def dlength(theta, P, act, fr=None):
    """Gradient dL/dtheta_j, j = 1..n (the signed moment arm about each hinge) [m/rad]."""
    fr = fr or _frames(theta, P)
    h = act["hinge"]
    zA, zF = point(theta, P, h, act["A"], fr), point(theta, P, h - 1, act["F"], fr)
    u = (zA - zF) / abs(zA - zF)
    return np.array([np.real(np.conj(u) * (dpoint(theta, P, h, act["A"], j, fr)
                                           - dpoint(theta, P, h - 1, act["F"], j, fr)))
                     for j in range(1, P["n"] + 1)])


def length_relative(tj, P, act):
    """Actuator length as a function of its own hinge angle only (adjacent bodies)."""
    J = P["J"][act["hinge"] - 1]
    return abs(J + np.exp(1j * tj) * (act["A"] - J) - act["F"])


def inverse_kinematics(L, P, act, near=0.0):
    """Hinge angle at which the actuator has length L (corrected document section 1.2).

    |J + e^{i t}(A - J) - F| = L  <=>  Re(e^{i t} w) = C, w = (A - J) conj(F - J),
    C = (|A - J|^2 + |F - J|^2 - L^2) / 2.  Two branches t = -arg w +- arccos(C/|w|);
    returns the one nearest ``near``, or nan when L is not reachable (|C| > |w|).
    """
    J = P["J"][act["hinge"] - 1]
    a, g = act["A"] - J, act["F"] - J
    w = a * np.conj(g)
    C = (abs(a) ** 2 + abs(g) ** 2 - L ** 2) / 2
    if abs(C) > abs(w):
        return np.nan
    base, half = -np.angle(w), np.arccos(C / abs(w))
    cands = np.array([base + half, base - half])
    cands = (cands + np.pi) % (2 * np.pi) - np.pi
    return cands[np.argmin(np.abs(cands - near))]


# --------------------------------------------------------------------------- forces
def sma_tension(theta, P, i, drive, fr=None):
    """Tension of SMA wire i [N] for drive = dict(mode='force', F=[..]) or
    dict(mode='strain', eps=[..], E=[..] or phase='M'/'A')."""
    s = P["sma"][i]
    if drive["mode"] == "force":
        return float(drive["F"][i])
    E = drive["E"][i] if "E" in drive else s["E_" + drive.get("phase", "M")]
    L_free = s["L0"] * (1.0 + drive["eps"][i])
    return max(E * s["area"] * (length(theta, P, s, fr) / L_free - 1.0), 0.0)


def spring_tension(theta, P, i, fr=None):
    """Tension of bias spring i [N] (linear, preload F_pre at theta = 0)."""
    s = P["spring"][i]
    return s["F_pre"] + s["k"] * (length(theta, P, s, fr) - s["L0"])


def residual(theta, P, drive):
    """R_j = dV/dtheta_j [N m] (zero at equilibrium)."""
    theta = np.atleast_1d(np.asarray(theta, float))
    fr = _frames(theta, P)
    R = np.zeros(P["n"])
    for i, s in enumerate(P["sma"]):
        R += sma_tension(theta, P, i, drive, fr) * dlength(theta, P, s, fr)
    for i, s in enumerate(P["spring"]):
        R += spring_tension(theta, P, i, fr) * dlength(theta, P, s, fr)
    for b in range(1, P["n"] + 1):
        zc = point(theta, P, b, P["cg"][b - 1], fr)
        for j in range(1, b + 1):
            R[j - 1] += P["mass"][b - 1] * P["g"] * np.real(zc - hinge(theta, P, j, fr))
    return R


def hinge_moments(theta, P, drive):
    """Direct moment balance (cross products) about each hinge of all forces on the bodies
    behind it [N m, CCW positive].  Independent check: equals -residual."""
    theta = np.atleast_1d(np.asarray(theta, float))
    M = np.zeros(P["n"])
    cross = lambda r, f: np.imag(np.conj(r) * f)
    acts = [(s, sma_tension(theta, P, i, drive)) for i, s in enumerate(P["sma"])] + \
           [(s, spring_tension(theta, P, i)) for i, s in enumerate(P["spring"])]
    for j in range(1, P["n"] + 1):
        c = hinge(theta, P, j)
        for s, T in acts:
            h = s["hinge"]
            zA, zF = point(theta, P, h, s["A"]), point(theta, P, h - 1, s["F"])
            fA = T * (zF - zA) / abs(zF - zA)          # force on the aft point A
            if h >= j:
                M[j - 1] += cross(zA - c, fA)
            if h - 1 >= j:
                M[j - 1] += cross(zF - c, -fA)
        for b in range(j, P["n"] + 1):
            zc = point(theta, P, b, P["cg"][b - 1])
            M[j - 1] += cross(zc - c, -1j * P["mass"][b - 1] * P["g"])
    return M


def hessian(theta, P, drive, h=1e-7):
    """dR/dtheta by central differences of the analytic R [N m/rad]."""
    theta = np.atleast_1d(np.asarray(theta, float))
    n = P["n"]
    H = np.zeros((n, n))
    for j in range(n):
        e = np.zeros(n)
        e[j] = h
        H[:, j] = (residual(theta + e, P, drive) - residual(theta - e, P, drive)) / (2 * h)
    return 0.5 * (H + H.T)


def sma_force_for_angle(theta, P):
    """One hinge: wire tension that holds the flap at theta (the document's force-driven
    formula, corrected): F_s = -(T_spring L_spring' + W y_cg') / L_sma'."""
    th = np.atleast_1d(float(theta))
    zero = dict(mode="force", F=[0.0] * P["n"])
    R0 = residual(th, P, zero)[0]
    return -R0 / dlength(th, P, P["sma"][0])[0]


# --------------------------------------------------------------------------- truth: bracketing
LIM = np.deg2rad(80.0)


def _roots_1d(f, lo=-LIM, hi=LIM, n=721):
    xs = np.linspace(lo, hi, n)
    fs = np.array([f(x) for x in xs])
    out = []
    for k in range(n - 1):
        if np.isnan(fs[k]) or np.isnan(fs[k + 1]):
            continue
        if fs[k] == 0.0:
            out.append(xs[k])
        elif fs[k] * fs[k + 1] < 0:
            out.append(brentq(f, xs[k], xs[k + 1], xtol=1e-15, rtol=1e-15, maxiter=200))
    return out


def _pick(roots, dfun):
    """Stable root (positive slope) nearest 0."""
    st = [r for r in roots if dfun(r) > 0]
    if not st:
        raise RuntimeError("no stable root in bracket")
    return min(st, key=abs)


def equilibrium_brentq(P, drive, lim=LIM):
    """Stable equilibrium angles (rad) by scanning for sign changes + brentq.

    One hinge: roots of R_1(theta).  Two hinges: nested - for each theta1 the stable root
    theta2*(theta1) of R_2, then roots of the reduced R_1(theta1, theta2*(theta1)).
    Returns (theta array, list of all roots found for the outer variable).
    """
    d = 1e-6
    if P["n"] == 1:
        f = lambda t: residual([t], P, drive)[0]
        roots = _roots_1d(f, -lim, lim)
        t = _pick(roots, lambda r: f(r + d) - f(r - d))
        return np.array([t]), roots

    def inner(t1):
        f2 = lambda t2: residual([t1, t2], P, drive)[1]
        try:
            return _pick(_roots_1d(f2, -lim, lim, 181), lambda r: f2(r + d) - f2(r - d))
        except RuntimeError:            # hinge 2 has no stable equilibrium in the bracket
            return np.nan

    def reduced(t1):
        t2 = inner(t1)
        return np.nan if np.isnan(t2) else residual([t1, t2], P, drive)[0]

    roots = _roots_1d(reduced, -lim, lim, 81)
    t1 = _pick(roots, lambda r: reduced(r + d) - reduced(r - d))
    return np.array([t1, inner(t1)]), roots


def equilibrium_kinematic(eps, P):
    """Rigid-wire limit (E -> inf) of the strain-driven case: L_sma = L0 (1 + eps) fixes each
    hinge angle by geometry alone (the corrected document section 1.2).  Hinges decouple."""
    eps = np.atleast_1d(eps)
    return np.array([inverse_kinematics(s["L0"] * (1 + eps[i]), P, s)
                     for i, s in enumerate(P["sma"])])


# --------------------------------------------------------------------------- Newton
def solve_newton(P, drive, theta0=None, tol=1e-12, maxit=50):
    """Newton on R(theta) = 0 with the (finite-difference) Hessian.
    Returns dict(theta, iterations, converged, history=|R| per iterate)."""
    th = np.zeros(P["n"]) if theta0 is None else np.array(theta0, float)
    hist = []
    for it in range(maxit + 1):
        R = residual(th, P, drive)
        hist.append(float(np.max(np.abs(R))))
        if hist[-1] < tol:
            return dict(theta=th, iterations=it, converged=True, history=hist)
        th = th - np.linalg.solve(hessian(th, P, drive), R)
    return dict(theta=th, iterations=maxit, converged=False, history=hist)


# --------------------------------------------------------------------------- document fixed point
def fixed_point_document(P, drive, theta0=None, tol=1e-10, maxit=200, blowup=np.pi):
    """The document's Algorithm 1 (physics corrected): Jacobi sweep over the hinges,
    spring strain from the moment balance (eq. 1.15) -> angle from the spring's inverse
    kinematics (eq. 1.7).  Status: 'converged', 'diverged' (|theta| > blowup),
    'unreachable' (needed spring length outside the spring's reach: eq. 1.7 has no
    solution) or 'maxit'.  history: list of theta iterates."""
    th = np.zeros(P["n"]) if theta0 is None else np.array(theta0, float)
    hist = [th.copy()]
    for it in range(1, maxit + 1):
        new = th.copy()
        for j in range(P["n"]):
            sp = P["spring"][j]
            dL = dlength(th, P, sp)[j]
            rest = residual(th, P, drive)[j] - spring_tension(th, P, j) * dL
            T_need = -rest / dL
            L_need = sp["L0"] + (T_need - sp["F_pre"]) / sp["k"]
            new[j] = inverse_kinematics(L_need, P, sp, near=th[j])
        hist.append(new.copy())
        if np.any(np.isnan(new)):
            return dict(theta=new, iterations=it, status="unreachable", history=hist)
        if np.any(np.abs(new) > blowup):
            return dict(theta=new, iterations=it, status="diverged", history=hist)
        if np.max(np.abs(new - th)) < tol:
            return dict(theta=new, iterations=it, status="converged", history=hist)
        th = new
    H = np.array(hist[-40:])
    if np.max(np.abs(H[-1] - H[-3])) < 1e-8 and np.max(np.abs(H[-1] - H[-2])) > 1e-6:
        return dict(theta=th, iterations=maxit, status="2-cycle", history=hist,
                    amplitude=np.abs(H[-1] - H[-2]) / 2)
    return dict(theta=th, iterations=maxit, status="maxit", history=hist)


def fixed_point_rate(P, drive, theta_star):
    """Iteration matrix I - D^-1 H at the equilibrium; returns (eigenvalues, spectral radius).
    One hinge: the single eigenvalue 1 - V''/(k L_spring'^2)."""
    th = np.atleast_1d(theta_star)
    H = hessian(th, P, drive)
    D = np.diag([s["k"] * dlength(th, P, s)[j] ** 2 for j, s in enumerate(P["spring"])])
    ev = np.linalg.eigvals(np.eye(P["n"]) - np.linalg.solve(D, H))
    return ev, float(np.max(np.abs(ev)))


def critical_spring_scale(P, drive):
    """Factor c such that scaling every bias-spring stiffness by c puts the fixed point at
    spectral radius 1 (it converges for larger springs).  Solved by brentq in log c."""
    def rho(logc):
        Q = {**P, "spring": [{**s, "k": s["k"] * np.exp(logc)} for s in P["spring"]]}
        nw = solve_newton(Q, drive)          # equals the brentq root (checked in __main__)
        assert nw["converged"]
        th = nw["theta"]
        return fixed_point_rate(Q, drive, th)[1] - 1.0
    return float(np.exp(brentq(rho, np.log(1e-2), np.log(1e3), xtol=1e-10)))


# --------------------------------------------------------------------------- the document, literally
def doc_inverse_literal(eta, a, f):
    """Document eqs. 1.5-1.9 as printed (a, f: complex, a in the hinge frame R_1, f in R_0).

    r = a - f (eq. 1.1), then cos from eq. 1.8 (with its sign error), sin from eq. 1.9,
    theta = atan2 (eq. 1.7).  Returns (theta, cos, sin): cos^2 + sin^2 != 1 in general."""
    a1, a2, f1, f2 = a.real, a.imag, f.real, f.imag
    r = a - f
    r1, r2 = r.real, r.imag
    c = (eta * r2 + f2 - (eta * r1 + f1) * a1 / a2) / (a2 + a1 ** 2 / a2)
    s = (-eta * r1 - f1 + a1 * c) / a2
    return np.arctan2(s, c), c, s


def doc_inverse_solved(eta, a, f):
    """Eqs. 1.5-1.6 solved correctly as a 2x2 linear system in (cos, sin) - still the
    wrong model (eta scales the vector r, not just its length): cos^2 + sin^2 != 1."""
    P_, Q_ = eta * (a - f).real + f.real, eta * (a - f).imag + f.imag
    n = abs(a) ** 2
    c = (a.real * P_ + a.imag * Q_) / n
    s = (a.real * Q_ - a.imag * P_) / n
    return np.arctan2(s, c), c, s


def doc_torque(F, a, f, theta):
    """Document eq. 1.12 for one actuator (a, f relative to the hinge, F its 'force')."""
    a1, a2 = a.real, a.imag
    r = a * np.exp(1j * theta) - f
    c, s = np.cos(theta), np.sin(theta)
    return F / abs(r) * ((a1 * c - a2 * s) * r.imag - (a1 * s + a2 * c) * r.real)


def sweep_strain(P, phase="M", eps=None):
    eps = np.linspace(0.0, -P["eps_max"], 9) if eps is None else eps
    out = []
    for e in eps:
        drive = dict(mode="strain", eps=[e] * P["n"], phase=phase)
        out.append(equilibrium_brentq(P, drive)[0])
    return np.asarray(eps), np.array(out)


def sweep_force(P, forces):
    """forces: array (m, n) of wire tensions [N]."""
    return np.array([equilibrium_brentq(P, dict(mode="force", F=list(F)))[0] for F in forces])


if __name__ == "__main__":
    np.set_printoptions(precision=5, suppress=True)
    deg = np.degrees
    for n in (1, 2):
        P = params(n)
        print("=" * 78, "\n%d hinge(s)" % n)
        print("  wire area %.4e m^2, L0 =" % P["sma"][0]["area"], [round(s["L0"], 6) for s in P["sma"]],
              " spring L0 =", [round(s["L0"], 6) for s in P["spring"]])
        th = np.full(n, 0.2)
        drv = dict(mode="strain", eps=[-0.02] * n, phase="M")
        print("  check virtual work vs direct moments:", residual(th, P, drv) + hinge_moments(th, P, drv))
        print("  kinematic (rigid wire) eps=0..-4% [deg]:")
        for e in np.linspace(0, -0.04, 5):
            print("    eps=%+.3f" % e, deg(equilibrium_kinematic([e] * n, P)))
        for ph in ("M", "A"):
            eps, th = sweep_strain(P, ph, np.linspace(0, -0.04, 5))
            print("  strain-driven E_%s [deg]:" % ph)
            for e, t in zip(eps, th):
                print("    eps=%+.3f" % e, deg(t))
        Fs = np.array([[10.0, 4.5], [12.0, 5.0], [14.0, 6.0], [16.0, 7.0], [18.0, 7.5]])[:, :n]
        print("  force-driven [deg]:")
        for F, t in zip(Fs, sweep_force(P, Fs)):
            print("    F=%s N" % F, deg(t))
        if n == 1:
            for tdeg in (-10, 0, 10, 20, 30):
                print("    F_s needed to hold %+d deg: %.5f N" % (tdeg, sma_force_for_angle(np.radians(tdeg), P)))
        print("  fixed point (document) vs Newton, from theta = 0:")
        cases = [("strain eps=-2%, E_M", dict(mode="strain", eps=[-0.02] * n, phase="M")),
                 ("strain eps=-2%, E_A", dict(mode="strain", eps=[-0.02] * n, phase="A")),
                 ("force F=%s" % Fs[2], dict(mode="force", F=list(Fs[2])))]
        for name, drv in cases:
            tb, _ = equilibrium_brentq(P, drv)
            nw = solve_newton(P, drv)
            fp = fixed_point_document(P, drv)
            ev, rho = fixed_point_rate(P, drv, tb)
            print("    %-22s brentq %s deg | Newton %d it %s | FP %s after %d it, rate eigs %s (rho=%.3f)"
                  % (name, deg(tb), nw["iterations"], deg(nw["theta"]), fp["status"], fp["iterations"],
                     np.real_if_close(ev), rho))
            if n == 1 and name.startswith("strain eps=-2%, E_M"):
                print("      FP iterates [deg]:", deg(np.array(fp["history"])[:6, 0]))
        drv = dict(mode="strain", eps=[-0.02] * n, phase="M")
        tb, _ = equilibrium_brentq(P, drv)
        fp = fixed_point_document(P, drv, theta0=tb + np.radians(0.01))
        print("  strain E_M, FP started 0.01 deg off the root: %s after %d it; iterates - root [deg]:"
              % (fp["status"], fp["iterations"]))
        print("   ", deg(np.array(fp["history"]) - tb)[:5].T)
        print("  strain E_M: spring-stiffness scale c -> FP status / iterations / rho (Newton its):")
        for c in (1, 10, 15, 19, 25, 40, 100):
            Q = {**P, "spring": [{**s, "k": s["k"] * c} for s in P["spring"]]}
            tq, _ = equilibrium_brentq(Q, drv)
            fp = fixed_point_document(Q, drv, maxit=500)
            nw = solve_newton(Q, drv)
            print("    c=%5g: %-11s %4d it  rho=%7.3f  theta*=%s deg (Newton %d it)%s"
                  % (c, fp["status"], fp["iterations"], fixed_point_rate(Q, drv, tq)[1], deg(tq),
                     nw["iterations"], "  2-cycle half-amplitude %s deg" % deg(fp["amplitude"])
                     if fp["status"] == "2-cycle" else ""))
        for ph in ("M", "A"):
            drv = dict(mode="strain", eps=[-0.02] * n, phase=ph)
            c = critical_spring_scale(P, drv)
            print("  strain-driven E_%s: fixed point converges only if the springs are >= %.3f x stiffer"
                  " (k1 >= %.0f N/m)" % (ph, c, c * P["spring"][0]["k"]))
    # the document's formulas, literally
    P = params(1)
    s, J = P["sma"][0], P["J"][0]
    a, f = s["A"] - J, s["F"] - J
    print("=" * 78)
    for eta in (1.0, 0.98):
        tl, cl, sl = doc_inverse_literal(eta, a, f)
        ts, cs, ss = doc_inverse_solved(eta, a, f)
        print("eta=%.2f: doc eq.1.8-1.9 theta=%.4f deg (cos^2+sin^2=%.4f); 2x2 solved %.4f deg (%.6f);"
              " correct %.4f deg" % (eta, deg(tl), cl ** 2 + sl ** 2, deg(ts), cs ** 2 + ss ** 2,
                                    deg(inverse_kinematics(eta * s["L0"], P, s))))
    a_off = 0.02 + 0.01j              # a horn with a1 != 0 exposes the sign error of eq. 1.8
    for eta in (1.0, 0.98):
        tl, cl, sl = doc_inverse_literal(eta, a_off, f)
        ts, cs, ss = doc_inverse_solved(eta, a_off, f)
        Q = {**P, "sma": [{**s, "A": J + a_off, "L0": abs(a_off - f)}]}
        print("a=0.02+0.01j, eta=%.2f: doc eq.1.8-1.9 theta=%.4f deg (cos^2+sin^2=%.4f); 2x2 solved"
              " %.4f deg; correct %.4f deg" % (eta, deg(tl), cl ** 2 + sl ** 2, deg(ts),
                                              deg(inverse_kinematics(eta * abs(a_off - f), Q, Q["sma"][0]))))
    print("doc eq. 1.16 F = E_M/A eps at eps=1%%: %.3e N; correct E_M A eps: %.3f N"
          % (s["E_M"] / s["area"] * 0.01, s["E_M"] * s["area"] * 0.01))
    th = np.radians(15.0)
    T = 10.0
    print("doc eq.1.12 torque of F=+10 N at 15 deg: %.6f N m; true CCW torque of 10 N tension: %.6f N m"
          % (doc_torque(T, a, f, th), -T * dlength([th], P, s)[0]))
    # document balance (eqs. 1.12-1.14) with tension-positive forces and W = flap weight
    drv = dict(mode="force", F=[15.0])
    sp = P["spring"][0]
    doc_sum = (doc_torque(15.0, a, f, th) + doc_torque(spring_tension([th], P, 0), sp["A"] - J, sp["F"] - J, th)
               + (P["cg"][0] - J).real * P["mass"][0] * G * np.cos(th))
    print("doc balance sum (1.13) = %.6f N m;  -residual (true CCW moment) = %.6f N m"
          % (doc_sum, -residual([th], P, drv)[0]))

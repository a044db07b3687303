"""Independent numpy reference for the circular-arc-track flap (seed 003).

Source: G. Arslan, *Development of kinetostatic design methodology for airplane
flap mechanisms*, MSc thesis, Izmir Institute of Technology, 2022 (Chapters 3-5,
Table 2, Table 3, Appendix C).  See ``docs/seeds/arc_track_flap.md`` for the
model, the reading that reproduces the tables and the list of document mistakes.

This module is plain numpy: it must never import jax or jaxmech.  It is the
"independent truth" the engine's tests compare against.

Model (everything in the plane of one flap mechanism, origin at the remote
centre of rotation A0, x towards the nose of the aircraft, y up, angles
counter-clockwise positive)::

    a2 e^{i(alpha0+theta12)} = a1 e^{i alpha0} + s34 e^{i(alpha0+theta13)}

* link 1: ground, carries the fixed pivot B0 = a1 e^{i alpha0} and two
  concentric circular slots centred at A0 (radii b1 > c1);
* link 2: the flap, rotates about A0 only (two pins F on the b1-slot and G on
  the c1-slot); its angle from the closed position is
  ``dth = theta12 - theta12_i``;
* link 3: the screw, pivoted at B0, direction angle alpha0 + theta13;
* link 4: the nut, pinned to the flap at A; the input is the nut travel
  s34 = |B0 A|.

Units: every public function takes and returns SI (m, rad, N, N m, kg, s),
except the ``DOC_*`` tables and ``__main__`` output, which use the document's
printed units (mm, deg, N, N mm).

Sign conventions
----------------
* ``M12`` > 0 is the air moment *per mechanism* that tends to close the flap
  (clockwise about A0); it enters the flap's moment balance as ``-M12``.
* ``F_input`` > 0: the nut pushes the flap at A along +e_s, the unit vector
  from B0 towards A (direction alpha0 + theta13).  ``F42 = F_input e_s``.
* ``G12G``, ``G12F`` > 0: the slot pushes the pin radially *outwards* (away
  from A0); the force of link 1 on link 2 at G is ``G12G * u_G`` with
  ``u_G = e^{i theta_G}``.  The document's negative G12G means the slot pulls
  the pin towards A0.
* ``T_R`` (raise = open the flap, against the load) and ``T_L`` (lower = close)
  are the screw torques of Shigley's square-thread formulas with axial load
  ``L = F_input``; T_L > 0 means the screw is self-locking (a positive torque
  is needed to lower).

The reading that reproduces Table 3 (see the doc): every mechanism (one screw
jack each, two per flap) carries HALF the flap's air moment but the FULL flap
weight ``m_flap g`` (12 kg); landing moments are interpolated linearly in the
nut travel s34.
"""

from __future__ import annotations

import numpy as np

# --------------------------------------------------------------------------
# Parameters
# --------------------------------------------------------------------------

_MM = 1e-3
_DEG = np.pi / 180.0


def params() -> dict:
    """Case-study parameters of the thesis (Table 2 and Section 5.2), in SI.

    **Returns** a dict of floats, named as in the thesis:

    * ``a1`` |A0 B0| [m], ``a2`` |A0 A| [m], ``a3`` screw length |B0 B| [m],
      ``alpha0`` angle x-A0-B0 [rad];
    * ``b1``, ``c1`` slot radii [m] (F on b1, G on c1), ``beta1`` angle of the
      b1-slot start F1,i [rad], ``beta2`` angle F1,i-A0-F2,i [rad], ``beta3``
      arc angle = flap rotation range [rad];
    * ``x_D``, ``y_D`` centre of mass of the flap, flap closed [m];
      ``m_flap`` [kg], ``g`` [m/s^2];
    * screw: mean radius ``r`` [m], lead ``l`` [m], friction ``f`` [-];
    * drive: ``s34_dot`` [m/s], ``s34_ddot`` [m/s^2];
    * loads: ``n_jacks`` (screw jacks/mechanisms per flap), flap air moments
      ``M12_cruise`` (flap closed), ``M12_landing_min`` (closed) and
      ``M12_landing_max`` (fully deployed) [N m], for the WHOLE flap.
    """
    return dict(
        a1=275 * _MM, a2=240 * _MM, a3=250 * _MM, alpha0=65 * _DEG,
        b1=350 * _MM, c1=300 * _MM,
        beta1=40 * _DEG, beta2=20 * _DEG, beta3=35 * _DEG,
        x_D=-30 * _MM, y_D=340 * _MM, m_flap=12.0, g=9.81,
        r=16 * _MM, l=8 * _MM, f=0.1,
        s34_dot=35 * _MM, s34_ddot=0.0,
        n_jacks=2,
        M12_cruise=750.0, M12_landing_min=220.0, M12_landing_max=650.0,
    )


# --------------------------------------------------------------------------
# Chapter 4: design method (inputs -> geometry)
# --------------------------------------------------------------------------

def design(p: dict) -> dict:
    """Chapter 4 design method: collinear initial and final nut positions.

    A traces a circle of radius a2 about A0 while the flap turns by beta3, so
    A_i A_f is a chord of length ``delta_s = 2 a2 sin(beta3/2)`` at distance
    ``h = a2 cos(beta3/2)`` from A0 (W = foot of the perpendicular = chord
    midpoint).  B0 is put on the chord's line, beyond A_i, so that the nut
    moves along a fixed screw direction between the two end positions:
    ``a1^2 = h^2 + t^2`` with ``t = |B0 W| = s34_i + delta_s/2``.

    **Requires** a1 > a2 (else s34_i <= 0: B0 would lie inside A's circle)
    and a1 > h (else t is not real).

    **Returns** (SI): ``delta_s``, ``h``, ``t``, ``s34_i``, ``s34_f``,
    ``theta12_i``, ``theta12_f``, ``theta13_i`` (= ``theta13_f``),
    ``mu_min`` = (pi - beta3)/2 (transmission angle at both stroke ends),
    ``A_i``, ``A_f`` (complex), the flap-link dimensions ``g2`` = |AD|,
    ``p2`` = |DG|, ``q2`` = |DF|, ``r_D`` = |A0 D|, ``theta_D_i``,
    ``alpha2`` = angle D-A0-A, ``sigma``, ``beta5``, ``beta6``, and the slot
    end points ``F1_i``, ``F1_f``, ``F2_i``, ``F2_f``.
    """
    a1, a2, al0, b3 = p["a1"], p["a2"], p["alpha0"], p["beta3"]
    delta_s = 2 * a2 * np.sin(b3 / 2)
    h = a2 * np.cos(b3 / 2)
    t = np.sqrt(a1**2 - h**2)
    s34_i = t - a2 * np.sin(b3 / 2)
    s34_f = s34_i + delta_s
    th12_i, th13_i = _angles(s34_i, p)
    th12_f, th13_f = _angles(s34_f, p)
    B0 = a1 * np.exp(1j * al0)
    A_i = B0 + s34_i * np.exp(1j * (al0 + th13_i))
    A_f = B0 + s34_f * np.exp(1j * (al0 + th13_i))
    D = p["x_D"] + 1j * p["y_D"]
    F1_i = p["b1"] * np.exp(1j * p["beta1"])
    F2_i = p["c1"] * np.exp(1j * (p["beta1"] + p["beta2"]))
    r_D = abs(D)
    g2, p2, q2 = abs(D - A_i), abs(F2_i - D), abs(F1_i - D)
    alpha2 = np.arccos((a2**2 + r_D**2 - g2**2) / (2 * a2 * r_D))
    theta_D_i = np.arctan2(p["y_D"], p["x_D"])
    sigma = 1.0 if theta_D_i > al0 + th12_i else -1.0
    beta5 = np.arccos((r_D**2 + p["c1"]**2 - p2**2) / (2 * r_D * p["c1"]))
    beta6 = np.arccos((r_D**2 + p["b1"]**2 - q2**2) / (2 * r_D * p["b1"]))
    return dict(
        delta_s=delta_s, h=h, t=t, s34_i=s34_i, s34_f=s34_f,
        theta12_i=th12_i, theta12_f=th12_f, theta13_i=th13_i,
        theta13_f=th13_f, mu_min=(np.pi - b3) / 2, A_i=A_i, A_f=A_f,
        g2=g2, p2=p2, q2=q2, r_D=r_D, theta_D_i=theta_D_i, alpha2=alpha2,
        sigma=sigma, beta5=beta5, beta6=beta6,
        F1_i=F1_i, F1_f=F1_i * np.exp(1j * b3),
        F2_i=F2_i, F2_f=F2_i * np.exp(1j * b3),
    )


# --------------------------------------------------------------------------
# Position, velocity, acceleration
# --------------------------------------------------------------------------

def _angles(s34, p):
    """theta12, theta13 [rad] from the cosine theorem, eqs. (3.1.1)-(3.1.2).

    Branch: theta12 in (0, pi) (A counter-clockwise of B0 seen from A0);
    theta13 in (0, pi)."""
    a1, a2 = p["a1"], p["a2"]
    th12 = np.arccos((a1**2 + a2**2 - s34**2) / (2 * a1 * a2))
    th13 = np.pi - np.arccos((a1**2 + s34**2 - a2**2) / (2 * a1 * s34))
    return th12, th13


def positions(s34, p: dict) -> dict:
    """All points for nut travel ``s34`` [m] (scalar or array), complex [m].

    ``dth = theta12 - theta12_i`` is the flap rotation from closed; every flap
    point is its closed position times ``e^{i dth}``.
    Returns ``theta12``, ``theta13``, ``dth``, ``theta_D``, ``theta_G``,
    ``theta_F`` [rad] and points ``A0, B0, A, B, D, G, F``.
    """
    s34 = np.asarray(s34, dtype=float)
    dsg = design(p)
    th12, th13 = _angles(s34, p)
    dth = th12 - dsg["theta12_i"]
    rot = np.exp(1j * dth)
    al0 = p["alpha0"]
    B0 = p["a1"] * np.exp(1j * al0)
    D = (p["x_D"] + 1j * p["y_D"]) * rot
    return dict(
        theta12=th12, theta13=th13, dth=dth,
        theta_D=dsg["theta_D_i"] + dth,
        theta_G=p["beta1"] + p["beta2"] + dth,   # = theta_D - beta5
        theta_F=p["beta1"] + dth,                # = theta_D - beta6
        A0=0j * s34, B0=B0 + 0j * s34,
        A=p["a2"] * np.exp(1j * (al0 + th12)),
        B=B0 + p["a3"] * np.exp(1j * (al0 + th13)),
        D=D, G=dsg["F2_i"] * rot, F=dsg["F1_i"] * rot,
    )


def kinematics(s34, p: dict, s34_dot=None, s34_ddot=None,
               doc_alpha12_sign=False) -> dict:
    """Angular rates and point accelerations (eqs. 3.3.1-3.3.4, 3.4.1-3.4.6).

    ``psi = theta13 - theta12``::

        omega12 = s34_dot / (a2 sin psi)
        omega13 = s34_dot / (s34 tan psi)           (the printed 3.3.2 has
                                                     tan instead of 1/tan)
        alpha12 = s34_ddot/(a2 sin psi)
                  + (omega12 - omega13) s34_dot cos psi / (a2 sin^2 psi)
        alpha13 = (s34 s34_ddot - s34_dot^2)/(s34^2 tan psi)
                  - (omega13 - omega12) s34_dot / (s34 sin^2 psi)

    ``doc_alpha12_sign=True`` uses the printed eq. (3.3.3), whose second term
    has the wrong sign; that is what Appendix C (Fig. 46) tabulates.
    Returns rates [rad/s, rad/s^2], complex velocities/accelerations of A and
    D [m/s, m/s^2], and ``aA_over_g``, ``aD_over_g`` (fractions, not %).
    """
    s34 = np.asarray(s34, dtype=float)
    sd = p["s34_dot"] if s34_dot is None else s34_dot
    sdd = p["s34_ddot"] if s34_ddot is None else s34_ddot
    pos = positions(s34, p)
    psi = pos["theta13"] - pos["theta12"]
    a2 = p["a2"]
    w12 = sd / (a2 * np.sin(psi))
    w13 = sd / (s34 * np.tan(psi))
    sgn = -1.0 if doc_alpha12_sign else 1.0
    al12 = sdd / (a2 * np.sin(psi)) + sgn * (w12 - w13) * sd * np.cos(psi) / (
        a2 * np.sin(psi) ** 2)
    al13 = (s34 * sdd - sd**2) / (s34**2 * np.tan(psi)) - (w13 - w12) * sd / (
        s34 * np.sin(psi) ** 2)
    # rigid rotation about A0: v = i w r, a = (i alpha - w^2) r
    vA, vD = 1j * w12 * pos["A"], 1j * w12 * pos["D"]
    aA = (1j * al12 - w12**2) * pos["A"]
    aD = (1j * al12 - w12**2) * pos["D"]
    return dict(omega12=w12, omega13=w13, alpha12=al12, alpha13=al13,
                vA=vA, vD=vD, aA=aA, aD=aD,
                aA_over_g=abs(aA) / p["g"], aD_over_g=abs(aD) / p["g"])


# --------------------------------------------------------------------------
# Loads and statics
# --------------------------------------------------------------------------

def air_moment(s34, scenario: str, p: dict, share=None):
    """Air moment on ONE mechanism [N m] (closing, > 0).

    ``share`` defaults to ``1/n_jacks`` (the thesis: "half of the external
    moment values are used").  Cruise: constant ``M12_cruise`` (given for the
    closed flap; the thesis' sheet keeps it constant over the stroke).
    Landing: linear in the nut travel s34 from ``M12_landing_min`` at s34_i
    to ``M12_landing_max`` at s34_f (Appendix C, Fig. 48: linear in s34, not
    in theta12).
    """
    share = 1.0 / p["n_jacks"] if share is None else share
    s34 = np.asarray(s34, dtype=float)
    if scenario == "cruise":
        return share * p["M12_cruise"] + 0.0 * s34
    if scenario == "landing":
        d = design(p)
        x = (s34 - d["s34_i"]) / d["delta_s"]
        return share * (p["M12_landing_min"]
                        + (p["M12_landing_max"] - p["M12_landing_min"]) * x)
    raise ValueError(f"scenario must be 'cruise' or 'landing', got {scenario!r}")


def screw_torques(L, p: dict):
    """Square-thread screw torques, thesis eqs. (3.6.9)-(3.6.10) [N m].

    ``tan(lambda) = l / (2 pi r)`` (lead angle; the thesis prints 1/(2 pi r))::

        T_R = r L (2 pi r f + l) / (2 pi r - f l)   (raise = open the flap)
        T_L = r L (2 pi r f - l) / (2 pi r + f l)   (lower = close the flap)
    """
    r, l, f = p["r"], p["l"], p["f"]
    c = 2 * np.pi * r
    return (r * L * (c * f + l) / (c - f * l),
            r * L * (c * f - l) / (c + f * l))


def statics(s34, M12, p: dict, weight_share=1.0) -> dict:
    """Kinetostatics of one mechanism (inertia neglected), closed form.

    Moment about A0 (slot reactions are radial, so they drop out)::

        F_input a2 sin(theta13 - theta12) - M12 - m g r_D cos(theta_D) = 0
        => F_input = (M12 + m g r_D cos theta_D) / (a2 sin(theta13 - theta12))

    Force balance (phi = alpha0 + theta13, screw direction)::

        G12G cos thG + G12F cos thF + F_input cos phi = 0
        G12G sin thG + G12F sin thF + F_input sin phi - m g = 0
        G12G = (F sin(phi - thF) - m g cos thF) / sin(thF - thG)
        G12F = (m g cos thG - F sin(phi - thG)) / sin(thF - thG)

    **Arguments:** ``s34`` [m], ``M12`` [N m] per mechanism (closing > 0),
    ``weight_share``: fraction of the flap weight carried by this mechanism
    (1.0 = the thesis' reading, 0.5 = a consistent half split).
    **Returns** [N, N m]: ``F_input``, ``G12G``, ``G12F``, ``T_R``, ``T_L``,
    ``weight_moment`` = m g r_D cos(theta_D) (negative: the weight helps to
    open), ``F34y`` = 0 (no transverse load on the nut: massless nut/screw).
    """
    pos = positions(s34, p)
    W = weight_share * p["m_flap"] * p["g"]
    r_D = abs(p["x_D"] + 1j * p["y_D"])
    th12, th13 = pos["theta12"], pos["theta13"]
    thG, thF, thD = pos["theta_G"], pos["theta_F"], pos["theta_D"]
    phi = p["alpha0"] + th13
    Wm = W * r_D * np.cos(thD)
    F = (M12 + Wm) / (p["a2"] * np.sin(th13 - th12))
    det = np.sin(thF - thG)
    G12G = (F * np.sin(phi - thF) - W * np.cos(thF)) / det
    G12F = (W * np.cos(thG) - F * np.sin(phi - thG)) / det
    T_R, T_L = screw_torques(F, p)
    return dict(F_input=F, G12G=G12G, G12F=G12F, T_R=T_R, T_L=T_L,
                weight_moment=Wm, F34y=0.0 * F)


def statics_linear_solve(s34, M12, p: dict, weight_share=1.0):
    """Check 1: solve the flap's 3x3 equilibrium (moment about A0, Fx, Fy)
    for (F_input, G12G, G12F) with numpy.linalg.solve; scalar s34 only."""
    pos = positions(s34, p)
    W = weight_share * p["m_flap"] * p["g"]
    e = np.exp(1j * (p["alpha0"] + pos["theta13"]))
    uG, uF = np.exp(1j * pos["theta_G"]), np.exp(1j * pos["theta_F"])
    cross = lambda a, b: (a.conjugate() * b).imag  # z-component of a x b
    K = np.array([[cross(pos["A"], e), 0.0, 0.0],
                  [e.real, uG.real, uF.real],
                  [e.imag, uG.imag, uF.imag]])
    rhs = np.array([M12 - cross(pos["D"], -1j * W), 0.0, W])
    return np.linalg.solve(K, rhs)


def statics_virtual_work_fd(s34, M12, p: dict, weight_share=1.0, h=1e-7):
    """Check 2: F_input from virtual work with central differences of the
    positions only: F_input = M12 dtheta12/ds34 + m g dy_D/ds34."""
    W = weight_share * p["m_flap"] * p["g"]
    pp, pm = positions(s34 + h, p), positions(s34 - h, p)
    return (M12 * (pp["theta12"] - pm["theta12"])
            + W * (pp["D"].imag - pm["D"].imag)) / (2 * h)


def statics_multiplier_form(s34, M12, p: dict, weight_share=1.0) -> dict:
    """Check 3, in the engine's form ``-Q + Phi_x^T lambda = tau e_u``.

    Coordinates q = (x2, y2, phi2, theta13) (flap pose: translation of the
    flap frame, which coincides with the ground frame when the flap is
    closed, and its rotation; screw angle), u = s34.  Constraints, each with a
    UNIT gradient so the multiplier is a force in newtons::

        Phi_G = |G(q)| - c1                       (pin G on the c1-slot)
        Phi_F = |F(q)| - b1                       (pin F on the b1-slot)
        Phi_A = A(q) - B0 - s34 e^{i(alpha0+theta13)}   (2 rows: nut pin A)

    Applied generalized force Q: weight -m g y^ at D, couple -M12 on phi2.
    Returns ``lam_G``, ``lam_F`` [N], ``lam_A`` (complex, [N]) and ``tau``.
    With this sign convention (constraint force on bodies = -Phi_x^T lambda):
    ``G12G = -lam_G``, ``G12F = -lam_F``, ``F42 = -lam_A`` and
    ``tau = F_input`` (the drive force along +s34).  Scalar s34 only.
    """
    pos = positions(s34, p)
    W = weight_share * p["m_flap"] * p["g"]
    e = np.exp(1j * (p["alpha0"] + pos["theta13"]))

    # Flap point P = (x2 + i y2) + e^{i phi2} P_loc, with P_loc its closed
    # position; at the solution x2 = y2 = 0, phi2 = dth, so
    # dP/d(x2, y2, phi2) = (1, i, i P)  (complex numbers as 2-vectors).
    def pose_jac(P):
        return np.array([1.0, 1j, 1j * P])

    rows = []
    for P, R in ((pos["G"], p["c1"]), (pos["F"], p["b1"])):
        u = P / abs(P)
        dP = pose_jac(P)
        rows.append([(u.conjugate() * d).real for d in dP] + [0.0])
    dA = pose_jac(pos["A"])
    dA_th13 = -s34 * 1j * e
    rows.append([d.real for d in dA] + [dA_th13.real])
    rows.append([d.imag for d in dA] + [dA_th13.imag])
    Phi_q = np.array(rows)                       # 4 x 4
    Phi_u = np.array([0.0, 0.0, -e.real, -e.imag])
    dD = pose_jac(pos["D"])
    Q = np.array([(-1j * W * d.conjugate()).real for d in dD] + [0.0])
    Q[2] -= M12
    lam = np.linalg.solve(Phi_q.T, Q)            # q rows: Phi_q^T lam = Q
    tau = Phi_u @ lam                            # u row (no applied load on u)
    return dict(lam_G=lam[0], lam_F=lam[1], lam_A=lam[2] + 1j * lam[3],
                tau=tau)


# --------------------------------------------------------------------------
# Fairing depth and validity checks
# --------------------------------------------------------------------------

def fairing_depth(p: dict, n=2001) -> dict:
    """Fairing-depth measures [m].

    * ``h`` = a2 cos(beta3/2): the thesis' figure for the depth saved against
      a dropped-hinge mechanism (whose fairing reaches down to A0); it is the
      distance from A0 to the screw line, i.e. the radial clearance of the
      nearest mechanism point (the chord midpoint W, which the nut passes).
    * ``y_min``: lowest local y (y is normal to the local x axis, which is
      perpendicular to gravity) of all mechanism parts over the stroke:
      screw B0-B (a3 long), nut A, both slot arcs; and ``lowest_part``.
    """
    d = design(p)
    s = np.linspace(d["s34_i"], d["s34_f"], n)
    pos = positions(s, p)
    cand = {
        "screw tip B": pos["B"].imag.min(),
        "screw pivot B0": pos["B0"].imag.min(),
        "nut A": pos["A"].imag.min(),
    }
    ang = np.linspace(0, p["beta3"], n)
    cand["b1-slot"] = (p["b1"] * np.sin(p["beta1"] + ang)).min()
    cand["c1-slot"] = (p["c1"] * np.sin(p["beta1"] + p["beta2"] + ang)).min()
    low = min(cand, key=cand.get)
    return dict(h=d["h"], y_min=cand[low], lowest_part=low, parts=cand)


def validity(p: dict, s34=None) -> dict:
    """The spreadsheet's red-cell checks (Section 5.3) as booleans (True = bad).

    1. ``pin_out_of_slot``: s34 < s34_i or theta12 - theta12_i > beta3
       (equivalently s34 > s34_f, theta12 grows monotonically with s34);
       with ``s34=None`` this checks the whole stroke (never true by design).
    2. ``c1_ge_b1``: c1 >= b1 (c1 must be the smaller radius).
    3. ``stroke_longer_than_screw``: s34 > a3, checked at the stroke end
       s34_f = s34_i + delta_s (Step 9 asks a3 slightly > s34_f).
    Also reported: ``design_infeasible`` (a1 <= a2, so s34_i <= 0, or
    a1 <= h) and the slider-crank triangle condition for a given s34.
    """
    d = design(p)
    eps = 1e-12
    out = dict(c1_ge_b1=bool(p["c1"] >= p["b1"]),
               stroke_longer_than_screw=bool(d["s34_f"] > p["a3"]),
               design_infeasible=bool(p["a1"] <= p["a2"] or p["a1"] <= d["h"]))
    if s34 is None:
        out["pin_out_of_slot"] = False
    else:
        s34 = np.asarray(s34, dtype=float)
        th12, _ = _angles(s34, p)
        out["pin_out_of_slot"] = (s34 < d["s34_i"] - eps) | (
            th12 - d["theta12_i"] > p["beta3"] + eps)
        out["triangle_violated"] = (s34 < abs(p["a1"] - p["a2"])) | (
            s34 > p["a1"] + p["a2"])
    return out


# --------------------------------------------------------------------------
# Tables
# --------------------------------------------------------------------------

#: Table 2, computed entries, as printed (mm, deg).
DOC_TABLE2 = dict(a3=250.0, s34_i=80.3, delta_s=144.3, g2=122.7, p2=197.1,
                  q2=319.5, alpha2=14.0)

#: Table 3 as printed (N, N mm); landing entries in printed order
#: ("min / max").  NB: G12G is printed "-3411 / -444", i.e. deployed first.
DOC_TABLE3 = {
    "cruise": dict(F_input=1623, G12G=-2204, G12F=3533, F34y=0,
                   T_R=4700, T_L=526),
    "landing": dict(F_input=(465, 1307), G12G=(-3411, -444),
                    G12F=(890, 3843), F34y=(0, 0), T_R=(1347, 3785),
                    T_L=(151, 424)),
}


def table2(p: dict) -> dict:
    """Table 2 computed entries in document units (mm, deg)."""
    d = design(p)
    return dict(a3=p["a3"] / _MM, s34_i=d["s34_i"] / _MM,
                delta_s=d["delta_s"] / _MM, g2=d["g2"] / _MM,
                p2=d["p2"] / _MM, q2=d["q2"] / _MM,
                alpha2=d["alpha2"] / _DEG)


def table3(p: dict, moment_share=None, weight_share=1.0) -> dict:
    """Table 3 in document units (N, N mm).

    Cruise: flap closed, M12 = share * M12_cruise.  Landing: (closed with
    M12_landing_min, deployed with M12_landing_max) -- ordered closed /
    deployed for every entry.  Defaults are the reading that reproduces the
    document: moment_share = 1/n_jacks, weight_share = 1.
    """
    d = design(p)
    share = 1.0 / p["n_jacks"] if moment_share is None else moment_share

    def conv(st):
        return dict(F_input=float(st["F_input"]), G12G=float(st["G12G"]),
                    G12F=float(st["G12F"]), F34y=0.0,
                    T_R=float(st["T_R"]) / _MM, T_L=float(st["T_L"]) / _MM)

    cr = conv(statics(d["s34_i"], share * p["M12_cruise"], p, weight_share))
    lo = conv(statics(d["s34_i"], share * p["M12_landing_min"], p,
                      weight_share))
    hi = conv(statics(d["s34_f"], share * p["M12_landing_max"], p,
                      weight_share))
    return {"cruise": cr, "landing": {k: (lo[k], hi[k]) for k in cr}}


def stroke_sweep(p: dict, scenario: str, n=1001, moment_share=None,
                 weight_share=1.0) -> dict:
    """Forces and torques over the whole stroke (SI arrays)."""
    d = design(p)
    s = np.linspace(d["s34_i"], d["s34_f"], n)
    M = air_moment(s, scenario, p, moment_share)
    st = statics(s, M, p, weight_share)
    st.update(s34=s, M12=M, dth=positions(s, p)["dth"])
    return st


def _fmt(x):
    return f"{x:.6g}"


def _main():
    p = params()
    d = design(p)
    print("Circular-arc-track flap, seed 003 -- reference values\n")
    print("Table 2 (computed entries)      computed      printed   match")
    t2 = table2(p)
    for k, v in t2.items():
        pr = DOC_TABLE2[k]
        dec = 0 if k in ("a3", "alpha2") else 1
        ok = round(v, dec) == pr
        print(f"  {k:8s} {v:22.6f} {pr:12g}   {'yes' if ok else 'NO'}")
    print(f"  theta12_i = {d['theta12_i']:.6f} rad, theta13_i = "
          f"{d['theta13_i']:.6f} rad, h = {d['h'] / _MM:.4f} mm, "
          f"t = {d['t'] / _MM:.4f} mm, mu_min = {d['mu_min'] / _DEG:.2f} deg")

    print("\nTable 3 (half air moment per jack, full weight)   computed"
          "  printed  match")
    t3 = table3(p)
    for k, v in t3["cruise"].items():
        pr = DOC_TABLE3["cruise"][k]
        print(f"  cruise  {k:8s} {v:14.4f} {pr:8g}   "
              f"{'yes' if round(v) == pr else 'NO'}")
    for k, (lo, hi) in t3["landing"].items():
        plo, phi_ = DOC_TABLE3["landing"][k]
        ok = (round(lo), round(hi)) == (plo, phi_)
        swp = (round(hi), round(lo)) == (plo, phi_)
        tag = "yes" if ok else ("yes as algebraic min/max (deployed printed first)" if swp
                                else "NO")
        print(f"  landing {k:8s} {lo:10.4f} / {hi:10.4f}   "
              f"{plo:g} / {phi_:g}   {tag}")

    print("\nOther readings (cruise, closed): F_input, G12G, G12F, T_R[N mm]")
    for lab, ms, ws in (("half moment, half weight", 0.5, 0.5),
                        ("full moment, full weight", 1.0, 1.0)):
        c = table3(p, ms, ws)["cruise"]
        print(f"  {lab:28s} {c['F_input']:.1f} {c['G12G']:.1f} "
              f"{c['G12F']:.1f} {c['T_R']:.1f}")

    print("\nChecks at s34_i, cruise (closed form / 3x3 solve / virtual "
          "work FD / multipliers)")
    M = 0.5 * p["M12_cruise"]
    st = statics(d["s34_i"], M, p)
    ls = statics_linear_solve(d["s34_i"], M, p)
    fd = statics_virtual_work_fd(d["s34_i"], M, p)
    mf = statics_multiplier_form(d["s34_i"], M, p)
    print(f"  F_input {_fmt(st['F_input'])} {_fmt(ls[0])} {_fmt(fd)} "
          f"{_fmt(mf['tau'])}")
    print(f"  G12G    {_fmt(st['G12G'])} {_fmt(ls[1])} -lam_G="
          f"{_fmt(-mf['lam_G'])}")
    print(f"  G12F    {_fmt(st['G12F'])} {_fmt(ls[2])} -lam_F="
          f"{_fmt(-mf['lam_F'])}")

    print("\nWhole stroke (per jack), SI")
    for sc in ("cruise", "landing"):
        sw = stroke_sweep(p, sc)
        for k in ("F_input", "G12G", "G12F", "T_R", "T_L"):
            v = sw[k]
            i, j = np.argmin(v), np.argmax(v)
            print(f"  {sc:7s} {k:7s} closed {v[0]:10.3f} deployed "
                  f"{v[-1]:10.3f}  min {v[i]:10.3f} @s34={sw['s34'][i]*1e3:7.2f}"
                  f" mm  max {v[j]:10.3f} @s34={sw['s34'][j]*1e3:7.2f} mm")
    s = np.linspace(d["s34_i"], d["s34_f"], 1001)
    kin = kinematics(s, p)
    print(f"\nAccelerations at s34_dot = 35 mm/s (percent of g): "
          f"|a_A| {100*kin['aA_over_g'].min():.5f}..{100*kin['aA_over_g'].max():.5f},"
          f" |a_D| {100*kin['aD_over_g'].min():.5f}..{100*kin['aD_over_g'].max():.5f}")
    k0 = kinematics(d["s34_i"], p)
    k0d = kinematics(d["s34_i"], p, doc_alpha12_sign=True)
    print(f"  alpha12(s34_i) = {k0['alpha12']:.6f} rad/s^2 (document eq. 3.3.3: "
          f"{k0d['alpha12']:.6f});  a_A = {k0['aA']*1e3:.4f} mm/s^2 "
          f"(sheet: {k0d['aA']*1e3:.4f})")
    fd_ = fairing_depth(p)
    print(f"\nFairing: h = {fd_['h']/_MM:.2f} mm; lowest mechanism point y = "
          f"{fd_['y_min']/_MM:.2f} mm ({fd_['lowest_part']})")
    print("Validity:", validity(p))


if __name__ == "__main__":
    _main()

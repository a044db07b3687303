"""Independent numpy/scipy reference for the retractable nose gear (seed 001_2d20636cf4490e47).

Ground truth for tests.  Plain numpy/scipy: it must not import jax or jaxmech.
See docs/seeds/landing_gear.md for the model, the citations and the list of report mistakes.

Model (the report's Figure 4, reconstructed from its equations)
---------------------------------------------------------------
* B: the gear pivot on the airframe (origin).  The gear leg AB (2.5 ft) rotates about B.
* C: the fixed pivot of the hydraulic cylinder on the airframe, at distance ``h`` from B.
  Gauss plane with the real axis along B->C:  C = h.
* P: the cylinder rod end on the gear, at distance ``d`` from B, rigidly on the gear.
  ``theta`` is the angle C-B-P, measured *clockwise* from BC so that an increasing theta is
  the report's clockwise retraction:  P(theta) = d * exp(-i theta).
* ``x``: the cylinder length |C - P| (pin to pin), 1.25 ft (retracted piston, gear down)
  to 2.0 ft (extended piston, gear up).
* Vector loop (complex, two real equations; phi is the cylinder direction P->C):
      d e^{-i theta} + x e^{i phi} - h = 0
  Eliminating phi gives the scalar closure used by the report (law of cosines):
      x^2 = d^2 + h^2 - 2 d h cos(theta).
* Design conditions: x(theta1) = 1.25 ft, x(theta1 + pi/2) = 2.0 ft, and - the report's
  implicit third condition (section 3.1, sin(theta1) = 1.25/h, cos(theta1) = d/h) - a right
  angle at P in the initial position (cylinder perpendicular to BP, transmission angle 90 deg).

Units: the report works in feet; every function takes and returns feet, seconds, radians
unless its name ends in ``_si``.  FT converts feet to metres (exact).
"""
import numpy as np
from scipy.integrate import quad
from scipy.optimize import root

FT = 0.3048                  # m per ft (exact)
AB = 2.5                     # ft, gear leg length (not needed by the kinematics)
X1, X2 = 1.25, 2.0           # ft, cylinder length gear-down / gear-up
STROKE = X2 - X1             # 0.75 ft
DTHETA = np.pi / 2           # rad, required rotation (clockwise)
T_DESIGN = 3.0               # s, the report's chosen retraction time
V_PISTON = STROKE / T_DESIGN  # 0.25 ft/s, the report's eq. (2)
T_REQUIRED = 4.0             # s, "menos de 4 segundos"

# The report's rounded numbers (section 3.1 / 3.2), for comparison only.
DOC = dict(d=0.64361, d2=-1.89361, h=1.4060, theta1=1.0953, theta1_deg=62.76,
           c0=2.3911, c1=1.8098, c2=3.6196, c3=0.9049, omega=np.pi / 6, v=0.25)


# --------------------------------------------------------------------------- design
def design_closed_form(x1=X1, x2=X2, dtheta=DTHETA):
    """Closed form of the report's design (right angle at P initially), any x1, x2.

    With h^2 = d^2 + x1^2 (right angle at P), cos(theta1) = d/h, sin(theta1) = x1/h, the
    final-position closure x2^2 = d^2 + h^2 - 2 d h cos(theta1 + dtheta) gives, for
    dtheta = pi/2,  d^2 + x1 d - (x2^2 - x1^2)/2 = 0  (report eq. 1 with x1 = 1.25), so
        d = (-x1 + sqrt(2 x2^2 - x1^2)) / 2,  h = hypot(d, x1),  theta1 = atan2(x1, d).
    For a general dtheta:  x2^2 = 2 d^2 + x1^2 - 2 (d^2 cos(dtheta) - d x1 sin(dtheta)).
    Returns (d, h, theta1) in ft, ft, rad.
    """
    a = 2.0 - 2.0 * np.cos(dtheta)
    b = 2.0 * x1 * np.sin(dtheta)
    c = x1 ** 2 - x2 ** 2
    d = (-b + np.sqrt(b * b - 4 * a * c)) / (2 * a)
    h = np.hypot(d, x1)
    return d, h, np.arctan2(x1, d)


def design_residual(z, x1=X1, x2=X2, dtheta=DTHETA):
    """Residual of the three design equations in the unknowns z = (d, h, theta1)."""
    d, h, th1 = z
    return np.array([
        d * d + h * h - 2 * d * h * np.cos(th1) - x1 ** 2,           # start: x = x1
        d * d + h * h - 2 * d * h * np.cos(th1 + dtheta) - x2 ** 2,  # end:   x = x2
        h * h - d * d - x1 ** 2,                                     # right angle at P
    ])


def design_solve(x1=X1, x2=X2, dtheta=DTHETA, guess=(1.0, 1.0, 1.0)):
    """Numerical solve (scipy.optimize.root, hybrid Powell) of the three design equations.

    Independent of the closed form: a generic 3x3 nonlinear solve from a neutral guess.
    Returns (d, h, theta1) in ft, ft, rad.
    """
    sol = root(design_residual, np.asarray(guess, float), args=(x1, x2, dtheta), tol=1e-14)
    if not sol.success:
        raise RuntimeError(sol.message)
    d, h, th1 = sol.x
    return d, h, th1


def design_family(theta1, x1=X1, x2=X2, dtheta=DTHETA):
    """(d, h) meeting only the two stroke conditions for a chosen theta1 (d <= h branch).

    Without the right-angle condition the design is a one-parameter family:
    subtracting the two closures gives d h = (x2^2 - x1^2) / (2 (cos th1 - cos(th1 + dtheta)))
    and d^2 + h^2 = x1^2 + 2 d h cos th1.  Returns (nan, nan) when no real design exists.
    """
    p = (x2 ** 2 - x1 ** 2) / (2 * (np.cos(theta1) - np.cos(theta1 + dtheta)))
    s = x1 ** 2 + 2 * p * np.cos(theta1)
    disc = s * s - 4 * p * p
    if p <= 0 or disc < 0:
        return np.nan, np.nan
    return np.sqrt((s - np.sqrt(disc)) / 2), np.sqrt((s + np.sqrt(disc)) / 2)


def design_si(x1=X1, x2=X2):
    """(d, h) in metres and theta1 in rad."""
    d, h, th1 = design_closed_form(x1, x2)
    return d * FT, h * FT, th1


D, H, THETA1 = design_closed_form()
THETA2 = THETA1 + DTHETA


# --------------------------------------------------------------------------- kinematics
def points(theta, d=D, h=H):
    """Complex positions (ft) of B, C, P for gear angle theta (clockwise from BC)."""
    theta = np.asarray(theta, float)
    return 0.0 * theta + 0j, h + 0.0 * theta + 0j, d * np.exp(-1j * theta)


def cylinder_length(theta, d=D, h=H):
    """x(theta) = |C - P| = sqrt(d^2 + h^2 - 2 d h cos theta)  [ft]."""
    return np.sqrt(d * d + h * h - 2 * d * h * np.cos(theta))


def gear_angle(x, d=D, h=H):
    """Inverse: theta(x) = arccos((d^2 + h^2 - x^2) / (2 d h)), branch theta in [0, pi]."""
    return np.arccos(np.clip((d * d + h * h - np.asarray(x, float) ** 2) / (2 * d * h), -1, 1))


def cylinder_angle(theta, d=D, h=H):
    """phi: direction of the cylinder P->C (rad, CCW from BC), from the complex loop."""
    _, C, P = points(theta, d, h)
    return np.angle(C - P)


def transmission_angle(theta, d=D, h=H):
    """Angle at P between P->B and P->C (rad). 90 deg at the start of the report's design."""
    x = cylinder_length(theta, d, h)
    return np.arccos(np.clip((d * d + x * x - h * h) / (2 * d * x), -1, 1))


def loop_residual(theta, x, d=D, h=H):
    """Complex loop d e^{-i theta} + x e^{i phi} - h with phi from the geometry (should be 0)."""
    return d * np.exp(-1j * theta) + x * np.exp(1j * cylinder_angle(theta, d, h)) - h


# --------------------------------------------------------------------------- drive laws
def motion_constant_speed(t, v=V_PISTON, d=D, h=H, x1=X1):
    """Constant piston speed x = x1 + v t (the physically consistent reading of eq. 2).

    From x^2 = d^2 + h^2 - 2 d h cos(theta):
        x xdot = d h sin(theta) thetadot
        xdot^2 + x xddot = d h (cos(theta) thetadot^2 + sin(theta) thetaddot).
    Returns dict of arrays: t, x, x_dot, x_ddot [ft, ft/s, ft/s^2], theta, theta_dot,
    theta_ddot [rad, rad/s, rad/s^2].  Valid for 0 <= t <= (x2 - x1)/v.
    """
    t = np.asarray(t, float)
    x = x1 + v * t
    xd = v + 0 * t
    xdd = 0 * t
    th = gear_angle(x, d, h)
    s, c = np.sin(th), np.cos(th)
    thd = x * xd / (d * h * s)
    thdd = (xd ** 2 + x * xdd - d * h * c * thd ** 2) / (d * h * s)
    return dict(t=t, x=x, x_dot=xd, x_ddot=xdd, theta=th, theta_dot=thd, theta_ddot=thdd)


def motion_linear_angle(t, omega=DTHETA / T_DESIGN, d=D, h=H, theta1=THETA1):
    """The report's eq. (3): theta = theta1 + omega t, omega = pi/6 rad/s (constant).

    Then x = sqrt(d^2 + h^2 - 2 d h cos theta) and
        xdot = d h sin(theta) omega / x,  xddot = (d h cos(theta) omega^2 - xdot^2) / x.
    """
    t = np.asarray(t, float)
    th = theta1 + omega * t
    thd = omega + 0 * t
    thdd = 0 * t
    x = cylinder_length(th, d, h)
    xd = d * h * np.sin(th) * thd / x
    xdd = (d * h * (np.cos(th) * thd ** 2 + np.sin(th) * thdd) - xd ** 2) / x
    return dict(t=t, x=x, x_dot=xd, x_ddot=xdd, theta=th, theta_dot=thd, theta_ddot=thdd)


def retraction_time_constant_speed(v=V_PISTON):
    """Time for the cylinder to go from 1.25 to 2 ft at constant speed v [s]."""
    return STROKE / v


def retraction_time_linear_angle(omega=DTHETA / T_DESIGN):
    """Time for theta to sweep pi/2 at constant rate omega [s]."""
    return DTHETA / omega


def retraction_time_by_integration(v=V_PISTON, d=D, h=H):
    """Cross-check of the constant-speed time: integral of dtheta / thetadot(theta)."""
    f = lambda th: d * h * np.sin(th) / (cylinder_length(th, d, h) * v)
    return quad(f, THETA1, THETA1 + DTHETA, epsabs=1e-13, epsrel=1e-13)[0]


def time_for_angle(theta, v=V_PISTON, d=D, h=H):
    """Constant piston speed: time at which the gear reaches angle theta [s]."""
    return (cylinder_length(theta, d, h) - X1) / v


# --------------------------------------------------------------------------- the report
def document_script(t):
    """Transcription of the report's Octave Listing 1 (rounded constants, as printed).

    theta = theta1 + pi/6 t (eq. 3); x = sqrt(f) (eq. 4); v = x / (3.6196 sin) (eq. 5
    evaluated on the *linear* theta); a = (0.9049 sin^2 v - cos v) / (3.6196 sin^2 sqrt f)
    (listing lines 19-22: the factor f of eq. 6 is missing from anum2).
    """
    t = np.asarray(t, float)
    th = DOC["theta1"] + (np.pi / 6) * t
    f = DOC["c0"] - DOC["c1"] * np.cos(th)
    x = np.sqrt(f)
    v = x / (DOC["c2"] * np.sin(th))
    a = (DOC["c3"] * np.sin(th) ** 2 * v - np.cos(th) * v) / (DOC["c2"] * np.sin(th) ** 2 * np.sqrt(f))
    return dict(t=t, theta=th, x=x, omega=v, alpha=a)


def document_eq6(theta):
    """The report's printed eq. (6) (with the factor f), as a function of theta."""
    f = DOC["c0"] - DOC["c1"] * np.cos(theta)
    w = np.sqrt(f) / (DOC["c2"] * np.sin(theta))
    return (DOC["c3"] * np.sin(theta) ** 2 * w - np.cos(theta) * w * f) / (
        DOC["c2"] * np.sin(theta) ** 2 * np.sqrt(f))


def document_angle_from_plotted_omega():
    """Angle swept by integrating the report's plotted omega(t) over 0..3 s [rad].

    If Figures 5 and 7 were consistent this would equal pi/2.
    """
    return quad(lambda t: float(document_script(t)["omega"]), 0.0, 3.0, epsabs=1e-12)[0]


def min_speed_for_requirement(t_req=T_REQUIRED):
    """Smallest constant piston speed that retracts in t_req [ft/s]."""
    return STROKE / t_req


if __name__ == "__main__":
    np.set_printoptions(precision=6, suppress=True)
    dc, hc, tc = design_closed_form()
    dn, hn, tn = design_solve()
    print("design (closed form): d=%.6f ft h=%.6f ft theta1=%.6f rad (%.4f deg)"
          % (dc, hc, tc, np.degrees(tc)))
    print("design (root solve) : d=%.6f ft h=%.6f ft theta1=%.6f rad" % (dn, hn, tn))
    print("  SI: d=%.6f m  h=%.6f m  x1=%.4f m x2=%.4f m  v=%.4f m/s"
          % (dc * FT, hc * FT, X1 * FT, X2 * FT, V_PISTON * FT))
    print("  report: d=%.5f h=%.4f theta1=%.4f rad; quadratic roots:" % (DOC["d"], DOC["h"], DOC["theta1"]),
          np.roots([1, X1, -(X2 ** 2 - X1 ** 2) / 2]))
    print("  d^2+h^2=%.6f  2dh=%.6f  (report 2.3911, 1.8098)" % (dc * dc + hc * hc, 2 * dc * hc))
    print("  report theta1 formula arcsin(1.25/0.64361): argument = %.4f > 1 (undefined);"
          " arcsin(1.25/h) = %.4f deg" % (X1 / DOC["d"], np.degrees(np.arcsin(X1 / hc))))
    print("  report's system with cos(theta2)=+sin(theta1): 2dh(cos-sin) = %.6f vs x2^2-x1^2 = %.4f"
          % (2 * dc * hc * (np.cos(tc) - np.sin(tc)), X2 ** 2 - X1 ** 2))
    print("  x(theta1)=%.6f  x(theta1+90deg)=%.6f ft" % (cylinder_length(tc), cylinder_length(tc + DTHETA)))
    print("  transmission angle start/end: %.3f / %.3f deg"
          % (np.degrees(transmission_angle(tc)), np.degrees(transmission_angle(tc + DTHETA))))
    print("  family (no right-angle condition), theta1=50,62.76,80 deg:",
          [tuple(np.round(design_family(np.radians(a)), 5)) for a in (50, np.degrees(tc), 80)])
    t = np.linspace(0, 3, 7)
    for name, m in (("constant piston speed 0.25 ft/s", motion_constant_speed(t)),
                    ("report's linear angle pi/6 rad/s", motion_linear_angle(t))):
        print(name)
        for k in ("t", "x", "x_dot", "theta", "theta_dot", "theta_ddot"):
            print("  %-10s" % k, m[k])
    print("retraction time: constant speed %.4f s (integral check %.10f s), linear angle %.4f s;"
          " requirement < %.1f s; min speed %.4f ft/s"
          % (retraction_time_constant_speed(), retraction_time_by_integration(),
             retraction_time_linear_angle(), T_REQUIRED, min_speed_for_requirement()))
    ds = document_script(t)
    print("report's Listing 1: omega", ds["omega"], "\n                    alpha", ds["alpha"])
    print("report's eq. (6) on the same theta:", document_eq6(ds["theta"]))
    print("angle from integrating the plotted omega over 3 s: %.6f rad (%.3f deg), not pi/2"
          % (document_angle_from_plotted_omega(), np.degrees(document_angle_from_plotted_omega())))
    print("max |loop residual| (constant speed):",
          np.max(np.abs(loop_residual(motion_constant_speed(t)["theta"], motion_constant_speed(t)["x"]))))

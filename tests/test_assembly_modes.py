"""Every loop keeps the assembly mode of the stroke's start, also the loops the user's
``branch`` indicator does not read, also after a gap.

The issue: a six-bar whose ``branch`` covered only its first loop (the README's four-bar
pattern applied to a six-bar) let its second loop come back from a gap (a stretch of the
crank turn where that loop cannot be assembled) on its mirror pose, reported CONVERGED.
Now every structural block the user's indicator leaves uncovered gets its own indicator
(``jaxmech/mechanism/branches.py``), so such a sample may be ``BRANCH``, never ``CONVERGED``.

Property: random Watt-II and Stephenson-III six-bars, written by hand with one scalar
indicator for loop 1 only, whose loop 1 is a Grashof crank-rocker (assemblable over the
whole turn) and whose second dyad is stretched beyond its reach over part of the turn (a
gap in loop 2, checked in closed form with poses on both sides), driven through the gap
once or twice, in strokes of 120 and 600 points.  The truth is the closed-form circle
intersection of each dyad (its two modes by the sign of the cross product of its two
links), independent of the solver: every CONVERGED sample has both loops in the modes
of the start and equals that mode's closed form to 1e-9 rad; loop 1's angles equal the
continuous (unwrapped) closed form as numbers, across gaps too; neighbouring converged
samples differ by less than half a turn, and across a gap loop 2's angles gain no whole
turn; no sample in a gap is CONVERGED, and BRANCH only where another mode has a pose; the
indicators (the user's and loop 2's automatic one) keep the start's signs where CONVERGED
and name the loops off them where BRANCH; and at least 90% of the samples after a gap
whose pose exists are CONVERGED (found again).

Also: the issue's regression (one Watt design through its gap, 120 and 600 points, every
start mode, metres and millimetres: no mirror pose CONVERGED, and BRANCH messages name
loop 2), and a four-bar without any indicator that keeps its guess's mode over a turn.
Programs compiled: one per mechanism and stroke length (designs batched, D per call).
"""

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

import jaxmech as jm  # noqa: E402

S = jm.Status
ACCURACY = 1e-9  # rad: a converged sample against its closed form
RECOVERED = 0.9  # share of the assemblable samples after a gap that must be found again
D = 8  # designs (or starts) per solve_stroke call: one compiled program per mechanism and stroke length

# ----------------------------------------------------------------------- the mechanisms
# Loop 1, both topologies: the four-bar O2-A-B-O4 (O2 at 0, O4 at d).  Loop 2: a dyad from a
# point P moved by loop 1, link f to the joint F, link g back to the ground pivot
# O6 = h + i k.  Watt II: P = E on the rocker (O4 + e e^{i(theta4 + gamma)}).  Stephenson
# III: P = C on the ternary coupler ABC (A + e e^{i(theta3 + gamma)}).
PARAMS = ("a", "b", "c", "d", "e", "gamma", "f", "g", "h", "k")
LENGTHS = ("a", "b", "c", "d", "e", "f", "g", "h", "k")


def _loop1(q, u, p):
    return p.a * jm.cis(u.theta2) + p.b * jm.cis(q.theta3) - p.c * jm.cis(q.theta4) - p.d


def _loop1_mode(q, u, p):
    return jnp.sin(q.theta4 - q.theta3)  # one scalar: loop 1 only, as in the README's four-bar


WATT = jm.Mechanism(
    name="watt_ii_loop1_indicator",
    coords=("theta3", "theta4", "theta5", "theta6"),
    inputs=("theta2",),
    params=PARAMS,
    lengths=LENGTHS,
    signed=("h", "k"),
    constraints=lambda q, u, p: [
        _loop1(q, u, p),
        p.d + p.e * jm.cis(q.theta4 + p.gamma) + p.f * jm.cis(q.theta5) - p.g * jm.cis(q.theta6) - (p.h + 1j * p.k),
    ],
    branch=_loop1_mode,
)

STEPHENSON = jm.Mechanism(
    name="stephenson_iii_loop1_indicator",
    coords=("theta3", "theta4", "theta5", "theta6"),
    inputs=("theta2",),
    params=PARAMS,
    lengths=LENGTHS,
    signed=("h", "k"),
    constraints=lambda q, u, p: [
        _loop1(q, u, p),
        p.a * jm.cis(u.theta2) + p.e * jm.cis(q.theta3 + p.gamma) + p.f * jm.cis(q.theta5) - p.g * jm.cis(q.theta6) - (p.h + 1j * p.k),
    ],
    branch=_loop1_mode,
)

MECHANISMS = {"watt": WATT, "stephenson": STEPHENSON}

#: A four-bar with no indicator at all: its one loop's mode is kept by its block's own.
FOURBAR_BARE = jm.Mechanism(
    name="fourbar_without_indicator",
    coords=("theta3", "theta4"),
    inputs=("theta2",),
    params=("a", "b", "c", "d"),
    lengths=("a", "b", "c", "d"),
    constraints=lambda q, u, p: [_loop1(q, u, p)],
)


# ----------------------------------------------------------------------- closed forms (numpy)
def dyad(p1, r1, p2, r2, sign):
    """The joint X with |X - p1| = r1 and |X - p2| = r2 (complex), in the mode whose cross
    product (X - p1) x (X - p2), i.e. sin(angle(X - p2) - angle(X - p1)), has the sign
    ``sign``; NaN where the two circles do not meet."""
    v = p2 - p1
    dist = np.abs(v)
    x = (dist**2 + r1**2 - r2**2) / (2 * dist)  # along p1 -> p2
    h2 = r1**2 - x**2
    with np.errstate(invalid="ignore"):
        h = np.where(h2 >= 0, np.sqrt(np.abs(h2)), np.nan)
    # Im(conj(X - p1) (X - p2)) = sign h dist: the cross product has the sign of ``sign``
    return p1 + v / dist * (x + 1j * sign * h)


def driver(kind, A, B, p):
    """Loop 2's moving point: E on the rocker (Watt) or C on the coupler (Stephenson)."""
    if kind == "watt":
        return p["d"] + p["e"] * np.exp(1j * (np.angle(B - p["d"]) + p["gamma"]))
    return A + p["e"] * np.exp(1j * (np.angle(B - A) + p["gamma"]))


def truth(kind, us, p, modes):
    """``(N, 4)`` closed-form ``(theta3, theta4, theta5, theta6)`` in the modes
    ``(sign sin(theta4 - theta3), sign sin(theta6 - theta5))``, angles in (-pi, pi];
    NaN where a loop cannot be assembled.  ``p``: one design (scalars)."""
    A = p["a"] * np.exp(1j * np.asarray(us))
    B = dyad(A, p["b"], p["d"] + 0j, p["c"], modes[0])
    P = driver(kind, A, B, p)
    O6 = p["h"] + 1j * p["k"]
    F = dyad(P, p["f"], O6, p["g"], modes[1])
    return np.stack([np.angle(B - A), np.angle(B - p["d"]), np.angle(F - P), np.angle(F - O6)], -1)


def modes_of(q):
    """The assembly modes of poses ``q (..., 4)``: the signs of the two dyads' cross products."""
    return np.stack([np.sign(np.sin(q[..., 1] - q[..., 0])), np.sign(np.sin(q[..., 3] - q[..., 2]))], -1)


def wrapped(x):
    return np.angle(np.exp(1j * x))


# ----------------------------------------------------------------------- random designs
def draw_design(kind, rng, theta0):
    """One random design with a gap in loop 2, its modes, or None (rejected).

    Loop 1 is a Grashof crank-rocker with margins ((b + c) - (d + a) and (d - a) - |b - c|
    at least 0.3: |A - O4| stays within (|b - c|, b + c) over the whole turn).  Loop 2's
    pivot O6 is placed, and f + g chosen, so that |P - O6| exceeds f + g over part of the
    turn (the gap) and is within reach at ``theta0`` and elsewhere; |f - g| stays below the
    smallest |P - O6|, so the dyad is never folded shut."""
    a, d = rng.uniform(0.5, 1.2), rng.uniform(2.5, 4.0)
    b, c = rng.uniform(1.5, 4.0, 2)
    if (b + c) - (d + a) < 0.3 or (d - a) - abs(b - c) < 0.3:
        return None
    modes = tuple(float(s) for s in rng.choice([-1.0, 1.0], 2))
    p = dict(a=a, b=b, c=c, d=d, e=rng.uniform(0.8, 2.5), gamma=rng.uniform(-np.pi, np.pi))
    turn = theta0 + np.linspace(0.0, 2 * np.pi, 1441)
    A = a * np.exp(1j * turn)
    B = dyad(A, b, d + 0j, c, modes[0])
    P = driver(kind, A, B, p)
    O6 = P.mean() + rng.uniform(1.5, 4.0) * np.exp(1j * rng.uniform(-np.pi, np.pi))
    rho = np.abs(P - O6)
    if rho.max() - rho[0] < 0.4:
        return None
    reach = rho[0] + rng.uniform(0.3, 0.7) * (rho.max() - rho[0])  # f + g
    fold = rho.min() - 0.3  # |f - g| below this
    if fold < 0.2:
        return None
    diff = rng.uniform(-1.0, 1.0) * fold
    p.update(f=(reach + diff) / 2, g=(reach - diff) / 2, h=O6.real, k=O6.imag)
    if min(p["f"], p["g"]) < 0.3:
        return None
    gap_share = np.mean(rho > reach)
    if not 0.05 <= gap_share <= 0.6:
        return None
    return {k: float(v) for k, v in p.items()}, modes


def check_design(kind, us, p, modes):
    """The closed form's own account of a design's stroke: loop 1 assemblable everywhere
    (Grashof crank-rocker, checked on the turn), loop 2 assemblable at the start, a gap in
    loop 2, and poses after it.  Returns the truth in the start's modes and the gap mask."""
    a, b, c, d = (p[k] for k in "abcd")
    s, l_ = min(a, b, c, d), max(a, b, c, d)
    assert a == s and s + l_ < a + b + c + d - s - l_, "loop 1 is not a Grashof crank-rocker"
    q = truth(kind, us, p, modes)
    assert np.all(np.isfinite(q[:, :2])), "loop 1 must be assemblable over the whole stroke"
    gap = ~np.all(np.isfinite(q), axis=-1)
    assert not gap[0] and np.any(gap), "the stroke must start assemblable and meet a gap"
    assert np.any(~gap[np.flatnonzero(gap)[0] :]), "loop 2 must be assemblable after the gap"
    # both modes of loop 2 exist exactly where the truth does (one dyad: one reach)
    mirror = truth(kind, us, p, (modes[0], -modes[1]))
    np.testing.assert_array_equal(np.isfinite(mirror[:, 2]), ~gap)
    # the closed form is in the modes it was asked for
    np.testing.assert_array_equal(modes_of(q[~gap]), np.broadcast_to(modes, (int(np.sum(~gap)), 2)))
    return q, gap


def random_batch(kind, seed, theta0, turns, n):
    rng = np.random.default_rng(seed)
    us = theta0 + np.linspace(0.0, turns * 2 * np.pi, n)
    designs = []
    while len(designs) < D:
        drawn = draw_design(kind, rng, theta0)
        if drawn is not None:
            designs.append(drawn)
    return us, [p for p, _ in designs], [m for _, m in designs]


# ----------------------------------------------------------------------- the property
def solve_and_check(kind, us, designs, modes):
    """Solve every design's stroke in one call (p leaves (D,), guess (D, 4) from the closed
    form in the chosen modes) and check the property; returns the Solution and per-design
    records for further checks."""
    mech = MECHANISMS[kind]
    truths = [check_design(kind, us, p, m) for p, m in zip(designs, modes)]
    guess = np.stack([q[0] for q, _ in truths])
    pb = {k: np.array([p[k] for p in designs]) for k in PARAMS}
    sol = jm.solve_stroke(mech, us, pb, guess)
    status, q = np.asarray(sol.status), np.asarray(sol.q)
    assert status.shape == (len(designs), us.size)
    # 0. the issue's count over the whole batch: post-gap samples CONVERGED in another mode
    mirror, post = [], 0
    for i, ((_, gap), m) in enumerate(zip(truths, modes)):
        after_gap = ~gap & (np.cumsum(gap) > 0)
        post += int(np.sum(after_gap))
        off = (status[i] == S.CONVERGED) & np.any(modes_of(q[i]) != np.asarray(m), axis=-1)
        mirror += [(i, j) for j in np.flatnonzero(off)]
    assert not mirror, (
        f"{kind}: {sum(1 for i, j in mirror if np.cumsum(truths[i][1])[j] > 0)} of {post} post-gap samples "
        f"({len(mirror)} in all) CONVERGED in another assembly mode; first: design {mirror[0][0]} "
        f"{designs[mirror[0][0]]} started in modes {modes[mirror[0][0]]}, at theta2 = {us[mirror[0][1]]!r}")
    report = []
    for i, ((q_true, gap), m) in enumerate(zip(truths, modes)):
        st_, qi = status[i], q[i]
        ok = st_ == S.CONVERGED
        where = f"{kind} design {i} {designs[i]} modes {m}"
        assert ok[0] and np.max(np.abs(qi[0] - guess[i])) < ACCURACY, f"{where}: the start is not the guess's pose"
        # 1. a converged sample is in the start's modes, both loops, and is that mode's closed form
        got = modes_of(qi[ok])
        off = np.any(got != np.asarray(m), axis=-1)
        assert not np.any(off), (
            f"{where}: {int(np.sum(off))} CONVERGED samples in another assembly mode, first at "
            f"theta2 = {us[ok][off][0]:.6f} (modes {got[off][0]})")
        err = np.abs(wrapped(qi[ok] - q_true[ok]))
        assert np.max(err, initial=0.0) < ACCURACY, f"{where}: {np.max(err):.3g} rad from the closed form"
        # 2. loop 1's angles as numbers: the continuous closed form (loop 1 has no gap)
        steps = np.abs(wrapped(np.diff(q_true[:, :2], axis=0)))
        assert np.max(steps) < 0.5, "the stroke is too coarse to unwrap loop 1's closed form"
        loop1 = np.unwrap(q_true[:, :2], axis=0)
        loop1 += 2 * np.pi * np.round((guess[i, :2] - loop1[0]) / (2 * np.pi))
        err1 = np.abs(qi[ok][:, :2] - loop1[ok])
        assert np.max(err1, initial=0.0) < ACCURACY, f"{where}: loop 1's angles {np.max(err1):.3g} off as numbers"
        # 3. continuity: neighbouring converged samples less than half a turn apart
        both = ok[:-1] & ok[1:]
        jumps = np.abs(np.diff(qi, axis=0))[both]
        assert np.max(jumps, initial=0.0) < np.pi, f"{where}: a jump of {np.max(jumps):.3g} rad between neighbours"
        # across a gap, loop 2's angles move by their true (wrapped) change, no whole turn added
        idx = np.flatnonzero(ok)
        across = np.flatnonzero(np.diff(idx) > 1)
        for j in across:
            before, after = idx[j], idx[j + 1]
            true_change = wrapped(q_true[after, 2:] - q_true[before, 2:])
            small = np.abs(true_change) < np.pi / 2
            moved = qi[after, 2:] - qi[before, 2:]
            turns_added = np.round((moved - true_change) / (2 * np.pi))
            assert np.all(turns_added[small] == 0), (
                f"{where}: loop 2 moved by {moved} across the gap {us[before]:.4f} -> {us[after]:.4f}, truly {true_change}")
        # 4. inside the gap nothing CONVERGED, and BRANCH only where another mode has a pose
        # (loop 1's mirror moves loop 2's driving point, so that pose may exist)
        assert not np.any(ok[gap]), f"{where}: CONVERGED inside the gap"
        others = [truth(kind, us, designs[i], (s1, s2)) for s1 in (1.0, -1.0) for s2 in (1.0, -1.0) if (s1, s2) != tuple(m)]
        anywhere = np.any([np.all(np.isfinite(o), axis=-1) for o in others], axis=0)
        assert not np.any((st_ == S.BRANCH) & gap & ~anywhere), f"{where}: BRANCH where no mode has a pose"
        # 5. the indicators: the user's (loop 1) and the automatic one of loop 2, the
        # determinant f g sin(theta5 - theta6) of its block, keep the start's signs where
        # CONVERGED; a BRANCH sample's flipped bits are the entries off those signs, and the
        # modes they name have a pose there in closed form
        br = np.asarray(sol.branch)[i]
        start_signs = np.array([m[0], -m[1]])
        assert np.all(np.sign(br[ok]) == start_signs), f"{where}: an indicator off the start's sign at a CONVERGED sample"
        branch = st_ == S.BRANCH
        bits = (np.sign(br[branch]) != start_signs) @ np.array([1, 2])
        np.testing.assert_array_equal(np.asarray(sol.flipped)[i][branch], bits)
        for j, signs in zip(np.flatnonzero(branch), np.sign(br[branch])):
            pose = truth(kind, us[j : j + 1], designs[i], (signs[0], -signs[1]))
            assert np.all(np.isfinite(pose)), f"{where}: BRANCH at theta2 = {us[j]:.6f} names modes {signs} with no pose"
        # 6. the poses after a gap are found again
        after_gap = ~gap & (np.cumsum(gap) > 0)
        share = np.mean(ok[after_gap])
        report.append(dict(after_gap=int(np.sum(after_gap)), recovered=int(np.sum(ok[after_gap])), passes=int(np.sum(np.diff(gap.astype(int)) == 1)),
                           counts=jm.status_counts(st_[after_gap])))
        assert share >= RECOVERED, f"{where}: only {share:.1%} of the assemblable samples after the gap converged: {report[-1]['counts']}"
    return sol, report


CASES = [  # (topology, seed, theta0, turns, points): four compiled programs in all (a
    # mechanism and a stroke length each), shared with the issue's test below
    ("watt", 11, 0.3, 1.5, 120),
    ("watt", 12, -1.1, 2.0, 600),
    ("stephenson", 21, 0.3, 1.5, 600),
    ("stephenson", 22, -1.1, 2.0, 600),
]


@pytest.mark.parametrize("kind,seed,theta0,turns,n", CASES)
def test_random_sixbars_keep_both_loops_modes_through_gaps(kind, seed, theta0, turns, n):
    us, designs, modes = random_batch(kind, seed, theta0, turns, n)
    _, report = solve_and_check(kind, us, designs, modes)
    assert sum(r["passes"] for r in report) >= len(designs)  # every stroke meets its gap
    if turns >= 2.0:
        assert all(r["passes"] >= 2 for r in report), report  # and these meet it twice


# ----------------------------------------------------------------------- the issue's case
#: One Watt design with a gap in loop 2 (|E - O6| beyond f + g over part of the turn, in
#: either mode of loop 1), started in each of the four mode combinations, in metres and in
#: millimetres.
ISSUE_P = dict(a=1.15, b=2.54, c=3.28, d=2.68, e=2.2, gamma=-0.88, f=1.05, g=1.98, h=0.66, k=1.74)
ISSUE_STARTS = [(m1, m2) for m1 in (1.0, -1.0) for m2 in (1.0, -1.0)]


@pytest.mark.parametrize("n", [120, 600])
def test_issue_watt_sixbar_no_mirror_pose_after_gap(n):
    """Before the fix (commit 7ceb4c3) these 8 strokes (2 turns from theta2 = 0.3) returned
    184 of 708 (120 points) and 932 of 3,568 (600 points) post-gap samples CONVERGED on loop
    2's mirror pose; now none, every post-gap pose is found again, and a BRANCH sample's
    message names the loops that flipped, loop 2 by its automatic indicator."""
    us = 0.3 + np.linspace(0.0, 2 * 2 * np.pi, n)
    millimetres = {k: (v * 1e3 if k in LENGTHS else v) for k, v in ISSUE_P.items()}
    designs = [ISSUE_P] * 4 + [millimetres] * 4  # D = 8: the property's compiled programs
    modes = ISSUE_STARTS * 2
    sol, report = solve_and_check("watt", us, designs, modes)
    assert sol.branches == ("branch", "loop 2")  # the user's scalar, then loop 2's own
    status = np.asarray(sol.status)
    np.testing.assert_array_equal(status[4:], status[:4], err_msg="metres and millimetres differ")
    assert all(r["recovered"] == r["after_gap"] for r in report), report
    assert all(r["passes"] == 2 for r in report), report
    named = set()
    for i, j in np.argwhere(status == S.BRANCH):
        msg = sol.message((i, j))
        flipped = [name for b, name in enumerate(sol.branches) if np.asarray(sol.flipped)[i, j] >> b & 1]
        assert flipped and "flipped" in msg and all(f"'{name}'" in msg for name in flipped), msg
        assert all(f"'{name}'" not in msg for name in sol.branches if name not in flipped), msg
        named.update(flipped)
    # (Which failed samples read BRANCH rather than INFEASIBLE depends on whether a start
    # happened to reach another mode's pose; test_gaps.py's
    # test_second_loop_flip_is_branch_naming_that_loop checks that a loop-2 flip is named.)


# ----------------------------------------------------------------------- no indicator at all
def test_fourbar_without_indicator_keeps_the_guess_mode_over_a_full_turn():
    """No ``branch`` at all: the loop's block gets the automatic indicator, and each start's
    mode is kept over the whole turn, angles equal to the continuous closed form."""
    p = dict(a=1.0, b=3.0, c=2.5, d=3.5)  # Grashof crank-rocker: 1 + 3.5 < 3 + 2.5
    us = 0.2 + np.linspace(0.0, 2 * np.pi, 181)
    A = p["a"] * np.exp(1j * us)
    truths = []
    for sign in (1.0, -1.0):
        B = dyad(A, p["b"], p["d"] + 0j, p["c"], sign)
        q = np.stack([np.angle(B - A), np.angle(B - p["d"])], -1)
        assert np.all(np.isfinite(q)) and np.all(np.sign(np.sin(q[:, 1] - q[:, 0])) == sign)
        truths.append(np.unwrap(q, axis=0))
    guess = np.stack([q[0] for q in truths])
    pb = {k: np.full(2, v) for k, v in p.items()}
    sol = jm.solve_stroke(FOURBAR_BARE, us, pb, guess)
    assert sol.branches == ("loop 1",)  # the automatic indicator, named after the loop
    st_, q = np.asarray(sol.status), np.asarray(sol.q)
    assert np.all(st_ == S.CONVERGED), jm.status_counts(st_)
    for i, q_true in enumerate(truths):
        assert np.max(np.abs(q[i] - q_true)) < ACCURACY, f"mode {i}: {np.max(np.abs(q[i] - q_true)):.3g} rad off"

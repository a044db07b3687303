"""The library's hand-written LAPACK and sort substitutes beside the calls they replace.

Three kernels avoid a LAPACK custom call or a sort because an executable holding one could
not be kept in the library's compile store (``jaxmech/_compile/stored.py``) with jaxlib 0.10:

- ``det``: ``jaxmech.solver.linalg.det_small`` (branch values: determinants of Jacobian
  blocks) against ``jnp.linalg.det``; 2x2 to 6x6, 8x8 and 12x12, vmapped over 100,000;
- ``cholesky``: ``jaxmech.design.nlp.cholesky_small`` (the SQP's Hessian shifts) against
  ``jnp.linalg.cholesky`` with ``ok = all(isfinite(L))``; 10x10 and 30x30 symmetric positive
  definite matrices vmapped over 10,000, one matrix unbatched (as ``sqp`` calls it) and 32
  10x10 (``second_order``'s stored SQP program runs 32 starts as vmapped lanes);
- ``top_k``: ``largest`` below (a copy of ``jaxmech.design.qp``'s private top-k by ranks,
  the QP polish's active set) against ``jax.lax.top_k``, k = 10 of vectors of length 40 and
  200 vmapped over 10,000, and one vector of length 40 unbatched (as the polish calls it)
  and vmapped over 32 (the lanes).

Per row, in one process, every program compiled with the library's options (fusion
emitters off): compile time (``jit(f).lower(x).compile()``) and warm run time (median of
repeated calls with ``block_until_ready``) of both versions, the largest difference of their
results (absolute and relative to the result's size; top-k: values and how many indices
differ), whether the compiled program calls LAPACK, and whether the LAPACK/sort version's
executable survives ``jax.experimental.serialize_executable``:

- ``roundtrip``: ``serialize``, ``deserialize_and_load`` and a call in this process, of the
  executable after it has run (the store's order: compile, run, store);
- ``roundtrip_before_a_call``: the same of a copy compiled anew and serialised before any call;
- ``fresh``: that copy loaded and called by a fresh Python process that has compiled nothing
  (a stored program's case; its own process, so a crash is recorded, not suffered);
- ``fresh_primed``: loaded by a fresh process that first compiled one small LAPACK program.

The hand-written executables are loaded by a fresh process too (``fresh`` on their side).
Loaded results are compared with the in-process call's, bitwise.  JAX's persistent
compilation cache is off.  Beside the rows: ``ok`` of both Cholesky versions on 10x10
matrices half of them indefinite.

Run: ``python -m benchmarks.lapack [--quick]``; writes ``results/lapack.json``.
"""

from __future__ import annotations

import json
import os
import pickle
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchmarks.common import base_parser, time_call, write_result

# the options the library compiles its programs with (jaxmech/_compile/xla.py: fusion
# emitters off); dropped where this jaxlib refuses them
OPTIONS = {"xla_cpu_use_fusion_emitters": False}


def compile_timed(fn, x):
    """``(compiled, seconds)`` of ``jit(fn).lower(x).compile()`` with the library's options."""
    import jax

    global OPTIONS
    t0 = time.perf_counter()
    try:
        compiled = jax.jit(fn, compiler_options=OPTIONS).lower(x).compile()
    except Exception as err:  # noqa: BLE001
        if not OPTIONS or "compiler_options" not in str(err) and "fusion_emitters" not in str(err):
            raise
        OPTIONS = {}
        t0 = time.perf_counter()
        compiled = jax.jit(fn).lower(x).compile()
    return compiled, time.perf_counter() - t0


def largest(x, k: int):
    """``(values, indices)`` of the ``k`` largest entries of ``x (m,)``, largest first: a copy
    of ``jaxmech.design.qp._largest`` (private there, so not imported)."""
    import jax.numpy as jnp

    i = jnp.arange(x.shape[0])
    ahead = (x[None, :] > x[:, None]) | ((x[None, :] == x[:, None]) & (i[None, :] < i[:, None]))
    rank = jnp.sum(ahead, axis=1)
    idx = jnp.argmax(rank[None, :] == jnp.arange(k)[:, None], axis=1)
    return x[idx], idx


def kernels(pair: str, k: int = 10):
    """``(hand-written, library call)`` per-sample functions of a pair."""
    import jax
    import jax.numpy as jnp

    from jaxmech.design.nlp import cholesky_small
    from jaxmech.solver.linalg import det_small

    if pair == "det":
        return det_small, jnp.linalg.det
    if pair == "cholesky":

        def lapack_cholesky(a):
            L = jnp.linalg.cholesky(a)
            return L, jnp.all(jnp.isfinite(L))

        return cholesky_small, lapack_cholesky
    return (lambda x: largest(x, k)), (lambda x: jax.lax.top_k(x, k))


def inputs(pair: str, size: int, batch: int, seed: int = 0):
    """The row's input, seeded (a fresh process rebuilds it); ``batch`` 0: one unbatched sample."""
    import numpy as np

    rng = np.random.default_rng(seed + 1000 * size)
    b = max(batch, 1)
    if pair == "det":
        x = rng.standard_normal((b, size, size))
    elif pair == "cholesky":  # B B^T / n + I: symmetric positive definite, condition ~10-100
        m = rng.standard_normal((b, size, size))
        x = m @ np.swapaxes(m, 1, 2) / size + np.eye(size)
    else:
        x = rng.standard_normal((b, size))
    return x if batch else x[0]


def program(pair: str, version: int, batch: int):
    import jax

    f = kernels(pair)[version]
    return jax.vmap(f) if batch else f


def digest(out) -> list[float]:
    """Sums of a result's arrays (a loaded executable's result is compared with them)."""
    import jax
    import numpy as np

    return [float(np.sum(np.asarray(a, dtype=np.float64))) for a in jax.tree_util.tree_leaves(out)]


def differences(pair: str, hand, lib) -> dict:
    import numpy as np

    if pair == "det":
        h, l_ = np.asarray(hand), np.asarray(lib)
        return {"max_abs_diff": float(np.max(np.abs(h - l_))), "max_rel_diff": float(np.max(np.abs(h - l_) / np.maximum(np.abs(l_), 1e-300)))}
    if pair == "cholesky":
        (hL, hok), (lL, lok) = [(np.asarray(a), np.asarray(b)) for a, b in (hand, lib)]
        return {"max_abs_diff": float(np.max(np.abs(hL - lL))), "max_rel_diff": float(np.max(np.abs(hL - lL)) / np.max(np.abs(lL))),
                "ok_differ": int(np.sum(hok != lok)), "ok_all": bool(np.all(hok) and np.all(lok))}
    (hv, hi), (lv, li) = [(np.asarray(a), np.asarray(b)) for a, b in (hand, lib)]
    return {"max_abs_diff": float(np.max(np.abs(hv - lv))), "indices_differ": int(np.sum(hi != li))}


def indefinite_check(size: int = 10, n: int = 1000) -> dict:
    """``ok`` of both Cholesky versions on matrices half of them indefinite (``A - s I``)."""
    import jax
    import numpy as np

    rng = np.random.default_rng(7)
    a = inputs("cholesky", size, n, seed=7)
    lo = np.linalg.eigvalsh(a)[:, 0]
    shift = np.where(rng.random(n) < 0.5, lo * 1.5, 0.0)  # half shifted past their smallest eigenvalue
    a = a - shift[:, None, None] * np.eye(size)
    expect = np.linalg.eigvalsh(a)[:, 0] > 0
    hand, lib = (jax.jit(jax.vmap(f), compiler_options=OPTIONS)(a)[1] for f in kernels("cholesky"))
    return {"matrices": n, "size": size, "positive_definite": int(expect.sum()), "hand_ok_wrong": int(np.sum(np.asarray(hand) != expect)),
            "lapack_ok_wrong": int(np.sum(np.asarray(lib) != expect))}


def roundtrip(compiled, x, ref: list[float]) -> dict:
    """``serialize`` / ``deserialize_and_load`` / call in this process."""
    from jax.experimental.serialize_executable import deserialize_and_load, serialize

    try:
        loaded = deserialize_and_load(*serialize(compiled))
        got = digest(loaded(x))
        return {"ok": got == ref, "same_result": got == ref}
    except Exception as e:  # noqa: BLE001 - the failure is the figure
        return {"ok": False, "error": f"{type(e).__name__}: {e}"[:500]}


def save(folder: Path, name: str, compiled, recipe: dict) -> Path | None:
    from jax.experimental.serialize_executable import serialize

    path = folder / f"{name}.pkl"
    try:
        path.write_bytes(pickle.dumps({"recipe": recipe, "payload": serialize(compiled)}))
    except Exception:  # noqa: BLE001 - recorded by roundtrip
        return None
    return path


def child(files: list[str], prime: bool) -> None:
    """Load each file's executable, call it on its recipe's input, print a JSON line each.
    ``prime``: compile one small LAPACK program (det and Cholesky of a 5x5) before the first
    program that calls LAPACK."""
    import jax

    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp
    from jax.experimental.serialize_executable import deserialize_and_load

    for f in files:
        doc = pickle.loads(Path(f).read_bytes())
        r = doc["recipe"]
        if prime and r["lapack"]:
            jax.block_until_ready(jax.jit(lambda a: (jnp.linalg.det(a), jnp.linalg.cholesky(a)))(jnp.eye(5) * 2.0))
            prime = False
        try:
            loaded = deserialize_and_load(*doc["payload"])
            out = {"name": r["name"], "ok": True, "digest": digest(loaded(inputs(r["pair"], r["size"], r["batch"])))}
        except Exception as e:  # noqa: BLE001
            out = {"name": r["name"], "ok": False, "error": f"{type(e).__name__}: {e}"[:500]}
        print(json.dumps(out), flush=True)


def fresh(files: list[Path], prime: bool = False) -> dict:
    """``{name: result}`` of loading ``files`` in one fresh process; a crash is recorded
    against the file it stopped at."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([os.getcwd(), os.environ.get("PYTHONPATH", "")]), JAXMECH_COMPILE_CACHE="0")
    cmd = [sys.executable, "-m", "benchmarks.lapack", "--child", *map(str, files)] + (["--prime"] if prime else [])
    done = subprocess.run(cmd, env=env, capture_output=True, text=True, check=False)
    got = {}
    for line in done.stdout.splitlines():
        if line.startswith("{"):
            d = json.loads(line)
            got[d.pop("name")] = d
    if done.returncode != 0:
        stopped = next((f.stem for f in files if f.stem not in got), None)
        if stopped:
            sig = f"signal {-done.returncode}" if done.returncode < 0 else f"exit {done.returncode}"
            got[stopped] = {"ok": False, "error": f"process crashed ({sig}) loading or calling it; {done.stderr.strip()[-300:]}"}
    return got


def row(pair: str, size: int, batch: int, repeat: int, folder: Path) -> dict:
    import jax

    x = jax.device_put(inputs(pair, size, batch))
    label = f"{pair}_{size}_{batch or 'single'}"
    r = {"pair": pair, "size": size, "batch": batch or None}
    outs, saved = [], {}
    for version, side in ((0, "hand"), (1, "lapack")):
        compiled, c = compile_timed(program(pair, version, batch), x)
        t0 = time.perf_counter()
        jax.block_until_ready(compiled(x))  # the warm-up call; slow programs get 3 timed calls
        rep = 3 if time.perf_counter() - t0 > 1.0 else repeat
        t = time_call(compiled, x, repeat=rep, warmup=0, min_time=0.2 if batch < 1000 else 0.0)
        out = compiled(x)
        outs.append(out)
        text = compiled.as_text()
        lapack = 'custom_call_target="lapack' in text
        ref = digest(out)
        r[side] = {"compile_s": c, "run_s": t.median, "run": dict(t), "calls_lapack": lapack, "has_sort": " sort(" in text or "topk" in text.lower(),
                   "digest": ref}
        name = f"{label}_{side}"
        recipe = {"name": name, "pair": pair, "size": size, "batch": batch, "lapack": lapack}
        if version == 1:
            # the store's order: compiled, run (and its text read), then serialised
            r[side]["roundtrip"] = roundtrip(compiled, x, ref)
            # the same program compiled anew and serialised before any call; this copy is
            # the one the fresh processes load
            again, _ = compile_timed(program(pair, version, batch), x)
            saved[side] = save(folder, name, again, recipe)
            r[side]["roundtrip_before_a_call"] = roundtrip(again, x, ref)
            del again
        else:
            saved[side] = save(folder, name, compiled, recipe)
        del compiled
    r.update(differences(pair, *outs))
    r["lapack_over_hand_run"] = r["lapack"]["run_s"] / r["hand"]["run_s"]
    r["lapack_over_hand_compile"] = r["lapack"]["compile_s"] / r["hand"]["compile_s"]
    r["_files"] = saved
    return r


def main(argv=None):
    parser = base_parser(__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=7, help="warm calls per version (median reported)")
    parser.add_argument("--child", nargs="+", default=None, help=__import__("argparse").SUPPRESS)
    parser.add_argument("--prime", action="store_true", help=__import__("argparse").SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        child(args.child, args.prime)
        return
    os.environ["JAXMECH_COMPILE_CACHE"] = "0"
    import jax

    jax.config.update("jax_enable_x64", True)
    jax.config.update("jax_enable_compilation_cache", False)  # every compile timed is a real one
    load0 = os.getloadavg()
    t_start = time.perf_counter()
    nd, nc, nt = (10_000, 1_000, 1_000) if args.quick else (100_000, 10_000, 10_000)
    # quick: no 12x12 (its hand-written program alone compiles in ~20 s)
    cases = ([("det", n, nd) for n in (2, 3, 4, 5, 6, 8) + (() if args.quick else (12,))] + [("cholesky", n, nc) for n in (10, 30)]
             + [("cholesky", n, 0) for n in (10, 30)] + [("cholesky", 10, 32)] + [("top_k", m, nt) for m in (40, 200)]
             + [("top_k", 40, 0), ("top_k", 40, 32)])
    # a throwaway compile first: the first compile of a process pays JAX's own start-up
    compile_timed(lambda a: a + 1.0, jax.numpy.ones(3))
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        for pair, n, b in cases:
            r = row(pair, n, b, 3 if args.quick else args.repeat, folder)
            rows.append(r)
            h, l_ = r["hand"], r["lapack"]
            print(f"{pair:8s} {n:3d} x{b or 1:7d}  compile hand {h['compile_s']:6.2f} s lapack {l_['compile_s']:5.2f} s  "
                  f"run hand {h['run_s'] * 1e3:8.3f} ms lapack {l_['run_s'] * 1e3:8.3f} ms ({r['lapack_over_hand_run']:5.2f}x)  "
                  f"max|diff| {r['max_abs_diff']:.1e}  LAPACK call {l_['calls_lapack']}  roundtrip {l_['roundtrip']['ok']}"
                  f" (before a call {l_['roundtrip_before_a_call']['ok']})", flush=True)
        # fresh processes: each LAPACK/sort executable alone (a crash ends its process), then
        # one process loading every hand-written one, priming LAPACK, and every library one
        for r in rows:
            f = r["_files"]["lapack"]
            r["lapack"]["fresh"] = fresh([f])[f.stem] if f else {"ok": False, "error": "not serialisable"}
        hand = [r["_files"]["hand"] for r in rows if r["_files"]["hand"]]
        lib = [r["_files"]["lapack"] for r in rows if r["_files"]["lapack"]]
        together = fresh(hand + lib, prime=True)
        for r in rows:
            for side, key in (("hand", "fresh"), ("lapack", "fresh_primed")):
                f = r["_files"][side]
                got = together.get(f.stem, {"ok": False, "error": "not reached (an earlier program crashed the process)"}) if f else \
                    {"ok": False, "error": "not serialisable"}
                if got.get("ok"):
                    got = {"ok": got["digest"] == r[side]["digest"], "same_result": got["digest"] == r[side]["digest"]}
                r[side][key] = got
            if r["lapack"]["fresh"].get("ok"):
                same = r["lapack"]["fresh"].pop("digest") == r["lapack"]["digest"]
                r["lapack"]["fresh"] = {"ok": same, "same_result": same}
            del r["_files"]
    for r in rows:
        l_ = r["lapack"]
        print(f"{r['pair']:8s} {r['size']:3d} x{r['batch'] or 1:7d}  hand fresh {r['hand']['fresh']['ok']}  lapack: roundtrip "
              f"{l_['roundtrip']['ok']}, fresh {l_['fresh']['ok']}, fresh primed {l_['fresh_primed']['ok']}"
              + ("" if l_["fresh"]["ok"] else f"  ({l_['fresh'].get('error', '')[:60]})"), flush=True)
    indefinite = indefinite_check()
    print("cholesky ok on half-indefinite 10x10 matrices:", indefinite)
    load1 = os.getloadavg()
    write_result("lapack", {"command": " ".join(["python -m benchmarks.lapack", *(argv if argv is not None else sys.argv[1:])]),
                            "quick": bool(args.quick), "load_average_before": list(load0), "load_average_after": list(load1),
                            "wall_s": time.perf_counter() - t_start, "compiler_options": OPTIONS, "rows": rows, "cholesky_indefinite": indefinite}, out_dir=args.out)


if __name__ == "__main__":
    main()

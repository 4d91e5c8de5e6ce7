"""A/B of one module's numba kernels inside env steps: this checkout's against another
git revision's, in one process, swapped between turns.

Replayed kernel calls mislead: a kernel fed the same recorded frames back to back finds
its maps in cache, and a change that wins there can lose in an env step, where the
renderer, the detector and pymunk take turns with the caches (an offset ``_sample_atlas``
once read 3–6 % faster on replayed frames and 2–9 % slower in env steps).
And two processes, or two checkouts taking turns, differ by more than a few per cent on
this VM from one minute to the next. So here one env steps in turns of ``--turn-steps``
random-action steps; before each turn the named kernels of ``--module`` are set to either
version (the module's globals are what its callers look up at every call), the version
that goes first alternating by round. The result is the median over rounds of the
per-round ratio of step times (after / before), with both versions' median µs per step.

Both versions are compiled here from source (``cache=False``), the revision's from
``git show REV:path`` of this checkout, run as a module of the same package (its relative
imports get today's modules). Only kernels that Python code calls are swapped: one that
another kernel calls was compiled into that caller (``find_lane_in_crop`` into
``fused.detect_frame``) and keeps its version there. Outputs are not compared: the tests
and ``tools/fingerprint.py`` hold those.

    python benchmarks/bench_kernel_ab.py --rev 31fe65d --module tfalda_sim.rendering.renderer \\
        --kernels _combine [--track oval|gen] [--observation lanes|image] [--rounds 60] [--json]
"""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import json
import statistics
import subprocess
import sys
import time
import types
from collections.abc import Callable
from pathlib import Path
from typing import Any

from _machine import host, pin_to_one_core

REPO = Path(__file__).resolve().parents[1]
"""The checkout whose code is "after" and whose git history holds "before"."""

TURN_STEPS = 200
"""Steps per turn (one version's kernels in place)."""

WARMUP_STEPS = 300
"""Steps per version before the rounds (the kernels compile on their first call)."""


class AbError(Exception):
    """A problem with the arguments, named with its fix."""


def module_source(module: str, rev: str) -> tuple[types.ModuleType, str]:
    """The imported ``module`` of this checkout and its source file's text at ``rev``."""
    try:
        current = importlib.import_module(module)
    except ImportError as e:
        raise AbError(f"unknown module {module!r} ({e}); give a module of this package, "
                      "e.g. tfalda_sim.rendering.renderer") from e
    origin = Path(getattr(current, "__file__", "") or "").resolve()
    try:
        relative = origin.relative_to(REPO)
    except ValueError as e:
        raise AbError(f"{module} is not a file of this checkout ({origin}); install it "
                      "editable (make install) and run this script from the checkout") from e
    done = subprocess.run(["git", "-C", str(REPO), "show", f"{rev}:{relative.as_posix()}"],
                          capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise AbError(f"git cannot show {relative} at revision {rev!r}: "
                      f"{done.stderr.strip()}; give a commit of this repository's history")
    return current, done.stdout


def compiled(module: types.ModuleType, source: str, tag: str) -> types.ModuleType:
    """``source`` run as a sibling of ``module`` (same package), its kernels uncached."""
    name = f"{module.__name__}__{tag}"
    copy = types.ModuleType(name)
    copy.__package__ = module.__package__
    copy.__file__ = f"<{tag}>"
    sys.modules[name] = copy  # dataclasses look their module up
    exec(compile(source.replace("cache=True", "cache=False"), f"<{tag} {module.__name__}>",
                 "exec"), copy.__dict__)
    return copy


def kernels_of(module: types.ModuleType, names: list[str], label: str) -> dict[str, Any]:
    missing = [n for n in names if not callable(getattr(module, n, None))]
    if missing:
        raise AbError(f"{label} has no function {', '.join(missing)}; give names of "
                      f"{module.__name__.rsplit('__', 1)[0]}'s functions")
    return {n: getattr(module, n) for n in names}


def run(rev: str, module: str, names: list[str], track: str, observation: str, rounds: int,
        turn_steps: int, quiet: bool) -> dict[str, Any]:
    import gymnasium as gym
    import numpy as np
    from tqdm import tqdm

    import tfalda_sim  # noqa: F401  (registers the env)

    current, old_source = module_source(module, rev)
    before = kernels_of(compiled(current, old_source, "before"), names, f"{module} at {rev}")
    after = kernels_of(compiled(current, Path(current.__file__).read_text(), "after"), names,
                       module)
    kwargs: dict[str, Any] = {"observation": observation}
    if track != "gen":
        kwargs["track"] = int(track) if track.isdigit() else track  # a seed, or a name
    try:
        env = gym.make("TfaldaTrack-v0", **kwargs)
    except ValueError as e:  # the env names the problem and the accepted values
        raise AbError(f"--track {track!r}: {e}") from e
    env.reset(seed=0)
    actions = np.random.default_rng(0).uniform(-1.0, 1.0, (1 << 16, 1)).astype(np.float32)
    k = 0

    def turn(kernels: dict[str, Any], steps: int) -> float:
        nonlocal k
        for name, f in kernels.items():
            setattr(current, name, f)
        t0 = time.perf_counter()
        for _ in range(steps):
            _, _, terminated, truncated, _ = env.step(actions[k % len(actions)])
            k += 1
            if terminated or truncated:
                env.reset()
        return time.perf_counter() - t0

    originals = {n: getattr(current, n) for n in names}
    per: dict[str, list[float]] = {"before": [], "after": []}
    try:
        turn(before, WARMUP_STEPS)
        turn(after, WARMUP_STEPS)
        with tqdm(total=rounds, desc="rounds", disable=quiet, file=sys.stderr) as bar:
            for r in range(rounds):
                order = (("before", before), ("after", after))
                for label, kernels in order if r % 2 == 0 else order[::-1]:
                    per[label].append(turn(kernels, turn_steps) / turn_steps * 1e6)
                bar.update(1)
    finally:
        for name, f in originals.items():
            setattr(current, name, f)
        env.close()
    ratios = [a / b for a, b in zip(per["after"], per["before"], strict=True)]
    return {
        "machine": {**host(), "pinned_to_one_core": True},
        "rev": rev, "module": module, "kernels": names, "track": track,
        "observation": observation, "rounds": rounds, "turn_steps": turn_steps,
        "before_us_per_step": statistics.median(per["before"]),
        "after_us_per_step": statistics.median(per["after"]),
        "ratio_after_to_before": statistics.median(ratios),
        "ratio_quartiles": [float(q) for q in np.percentile(ratios, [25, 75])],
    }


def table(result: dict[str, Any]) -> str:
    m = result["machine"]
    q1, q3 = result["ratio_quartiles"]
    return "\n".join([
        f"machine: {m['cores']} cores of {m['cpu']} ({m['simd']}; pinned to one)",
        f"{result['module']}: {', '.join(result['kernels'])}; before = {result['rev']}, "
        f"after = this checkout; {result['observation']} on {result['track']}, "
        f"{result['rounds']} rounds of {result['turn_steps']} steps each",
        f"{'before [µs/step]':<28}{result['before_us_per_step']:10.0f}",
        f"{'after [µs/step]':<28}{result['after_us_per_step']:10.0f}",
        f"{'after / before (median)':<28}{result['ratio_after_to_before']:10.3f}"
        f"   (quartiles {q1:.3f}–{q3:.3f})",
    ])


def ab_parser(doc: str) -> argparse.ArgumentParser:
    """An A/B script's parser (its docstring's first paragraph), with ``--rev`` and
    ``--json``."""
    parser = argparse.ArgumentParser(description=doc.split("\n\n")[0])
    parser.add_argument("--rev", required=True, help="the git revision of the 'before' code")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = ab_parser(__doc__)
    parser.add_argument("--module", required=True,
                        help="the module whose kernels are swapped, e.g. "
                             "tfalda_sim.rendering.renderer")
    parser.add_argument("--kernels", required=True,
                        help="comma-separated function names of that module")
    parser.add_argument("--track", default="oval",
                        help="a named track, a generator seed, or 'gen' for a new generated "
                             "track per reset")
    parser.add_argument("--observation", default="lanes", choices=("lanes", "image"))
    parser.add_argument("--rounds", type=int, default=60, help="rounds of two turns")
    parser.add_argument("--turn-steps", type=int, default=TURN_STEPS, help="steps per turn")
    args = parser.parse_args(argv)
    if args.rounds < 1 or args.turn_steps < 1:
        parser.error("--rounds and --turn-steps must be ≥ 1")
    names = [n.strip() for n in args.kernels.split(",") if n.strip()]
    if not names:
        parser.error("--kernels names no function")
    pin_to_one_core()
    return report("bench_kernel_ab.py", lambda: run(
        args.rev, args.module, names, args.track, args.observation, args.rounds,
        args.turn_steps, quiet=args.json), table, args.json)


def report(script: str, work: Callable[[], dict[str, Any]],
           table: Callable[[dict[str, Any]], str], as_json: bool,
           failure: type[Exception] | None = None) -> int:
    """Run ``work`` and print its result (``table``'s, or JSON); the exit code: 0, 2 for
    an argument's problem (``AbError``), 1 for a ``failure`` (its message says why), 130
    for a Ctrl-C (nothing to report)."""
    try:
        result = work()
    except AbError as e:
        print(f"{script}: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"{script}: interrupted; nothing measured to report", file=sys.stderr)
        return 130
    except Exception as e:
        if failure is None or not isinstance(e, failure):
            raise
        print(f"{script}: error: {e}", file=sys.stderr)
        return 1
    print(json.dumps(result, indent=2) if as_json else table(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())

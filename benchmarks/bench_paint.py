"""Benchmark of the lazy marking paint (``tfalda_sim.tracks.raster._paint_listed``) on the
tiles an env really paints: this checkout's kernel against another git revision's, in one
process, in turns (a new generated track's ground is painted lazily, as the car comes to
see it, so this paint is part of every step on generated tracks).

    python benchmarks/bench_paint.py --rev REV [--steps 3000] [--rounds 9] [--json]

The work: a "lanes" env on default generated tracks (a new track per reset), uniformly
random actions from a fixed seed, ``--steps`` steps; after every reset and step the
level-0 tiles its scene's marking map painted are listed (the reset's first view
included). Both versions then paint exactly those lists, one call a list (one a frame, as
in the env), each through its own module's ``TiledMarkingMap`` on the same memory (zeroed
between passes, untimed; the memory is written once before, so no pass pays its page
faults), the version that goes first alternating by round; only the paint calls are
timed. Every pass's paint is compared with the other version's: a
difference is an error (exit 1), since the paint must stay bit-identical.

Both versions are compiled here from source (``cache=False``, as ``bench_kernel_ab.py``
does): the revision's ``tracks/raster.py`` from ``git show REV:…``. Reported: µs per
painted tile and per call of each version (medians over rounds) and the median per-round
ratio after / before, with the core count; a table, or ``--json``.
"""

from __future__ import annotations

import hashlib
import statistics
import sys
import time
from pathlib import Path
from typing import Any

from _machine import host, pin_to_one_core
from bench_kernel_ab import AbError, ab_parser, compiled, module_source, report

MODULE = "tfalda_sim.tracks.raster"
"""The module whose kernel is compared."""

KERNEL = "_paint_listed"
"""The kernel a lazy scene's fill calls for its level-0 tiles."""

MAX_STEPS = 100_000
"""Most env steps recorded: their episodes' tracks and tile lists stay in memory (≈ 1800
tracks and 10 MB of lists at most)."""


def record(steps: int, quiet: bool) -> list[tuple[Any, list[Any]]]:
    """``(track, [tile lists])`` per episode of the work (see the module's docstring)."""
    import gymnasium as gym
    import numpy as np
    from tqdm import tqdm

    import tfalda_sim  # noqa: F401  (registers the env)

    env = gym.make("TfaldaTrack-v0")
    inner = env.unwrapped
    env.reset(seed=0)
    actions = np.random.default_rng(0).uniform(-1.0, 1.0, (steps, 1)).astype(np.float32)

    def painted() -> tuple[Any, int]:
        marking = inner._scene.tiles.marking  # type: ignore[attr-defined]
        return marking, int(marking._n_record[0])

    episodes: list[tuple[Any, list[Any]]] = []
    marking, n = painted()
    lists = [marking._record[:n].copy()]
    try:
        for k in tqdm(range(steps), desc="recording", disable=quiet, file=sys.stderr):
            _, _, terminated, truncated, _ = env.step(actions[k])
            now, m = painted()
            if now is marking and m > n:
                lists.append(marking._record[n:m].copy())
            marking, n = now, m
            if terminated or truncated:
                episodes.append((marking.track, lists))
                env.reset()
                marking, n = painted()
                lists = [marking._record[:n].copy()]
        episodes.append((marking.track, lists))
    finally:
        env.close()
    return episodes


def run(rev: str, steps: int, rounds: int, quiet: bool) -> dict[str, Any]:
    import numpy as np
    from tqdm import tqdm

    current, old_source = module_source(MODULE, rev)
    modules = {"before": compiled(current, old_source, "before"),
               "after": compiled(current, Path(current.__file__).read_text(), "after")}
    if not callable(getattr(modules["before"], KERNEL, None)):
        raise AbError(f"{MODULE} at {rev} has no {KERNEL}; give a revision with the lazy "
                      "marking map (tiles painted on demand)")
    episodes = record(steps, quiet)
    # Each version paints through its own module's map (its own arguments: chunk boxes,
    # row masks), made afresh for each episode and pass (untimed) on one memory.
    shapes = [current.map_geometry(track)[1] for track, _ in episodes]
    memory = np.ones((max(r for r, _ in shapes), max(c for _, c in shapes)), np.uint8)
    n_tiles = sum(len(tiles) for _, lists in episodes for tiles in lists)
    n_calls = sum(len(lists) for _, lists in episodes)
    first: list[bytes] = []  # a digest of each episode's paint, as the first pass made it

    def paint(label: str) -> float:
        elapsed = 0.0
        for k, ((track, lists), (rows, cols)) in enumerate(zip(episodes, shapes, strict=True)):
            view = memory[:rows, :cols]
            view[:] = 0
            try:
                m = modules[label].TiledMarkingMap(track, labels=False, intensity=view)
                m.paint_args  # noqa: B018  (made before the clock starts)
                for tiles in lists:
                    t0 = time.perf_counter()
                    m.paint_level0(tiles)
                    elapsed += time.perf_counter() - t0
            except Exception as error:  # a revision whose map or kernel differs
                raise AbError(f"{MODULE} at {rev} cannot paint this checkout's tile lists "
                              f"({type(error).__name__}: {error}); give a revision with the "
                              "same TiledMarkingMap and paint_level0") from error
            digest = hashlib.blake2b(np.ascontiguousarray(view)).digest()
            if len(first) <= k:
                first.append(digest)
            elif digest != first[k]:
                raise PaintDiffers(f"the two versions paint episode {k}'s tiles differently "
                                   f"(track seed {track.seed}); the paint must stay "
                                   "bit-identical")
        return elapsed

    paint("before")  # compiles (uncached) and checks, untimed
    paint("after")
    per: dict[str, list[float]] = {"before": [], "after": []}
    with tqdm(total=rounds, desc="rounds", disable=quiet, file=sys.stderr) as bar:
        for r in range(rounds):
            order = ("before", "after") if r % 2 == 0 else ("after", "before")
            for label in order:
                per[label].append(paint(label))
            bar.update(1)
    ratios = [a / b for a, b in zip(per["after"], per["before"], strict=True)]
    before, after = statistics.median(per["before"]), statistics.median(per["after"])
    return {
        "machine": {**host(), "pinned_to_one_core": True},
        "rev": rev, "steps": steps, "rounds": rounds, "episodes": len(episodes),
        "calls": n_calls, "tiles": n_tiles, "identical": True,
        "before_ms": before * 1e3, "after_ms": after * 1e3,
        "before_us_per_tile": before / max(1, n_tiles) * 1e6,
        "after_us_per_tile": after / max(1, n_tiles) * 1e6,
        "before_us_per_call": before / max(1, n_calls) * 1e6,
        "after_us_per_call": after / max(1, n_calls) * 1e6,
        "ratio_after_to_before": statistics.median(ratios),
        "ratio_quartiles": [float(q) for q in np.percentile(ratios, [25, 75])],
    }


class PaintDiffers(Exception):
    """The two versions' paint differs."""


def table(r: dict[str, Any]) -> str:
    m = r["machine"]
    q1, q3 = r["ratio_quartiles"]
    return "\n".join([
        f"machine: {m['cores']} cores of {m['cpu']} ({m['simd']}; pinned to one)",
        f"{MODULE}.{KERNEL}: before = {r['rev']}, after = this checkout; the tiles a lanes "
        f"env painted in {r['steps']} random steps on generated tracks ({r['episodes']} "
        f"episodes, {r['calls']} calls, {r['tiles']} tiles), {r['rounds']} rounds; paint "
        "identical",
        f"{'':<12}{'ms a pass':>12}{'µs/tile':>10}{'µs/call':>10}",
        f"{'before':<12}{r['before_ms']:12.1f}{r['before_us_per_tile']:10.2f}"
        f"{r['before_us_per_call']:10.1f}",
        f"{'after':<12}{r['after_ms']:12.1f}{r['after_us_per_tile']:10.2f}"
        f"{r['after_us_per_call']:10.1f}",
        f"after / before (median of rounds) {r['ratio_after_to_before']:.3f}"
        f"   (quartiles {q1:.3f}–{q3:.3f})",
    ])


def main(argv: list[str] | None = None) -> int:
    parser = ab_parser(__doc__)
    parser.add_argument("--steps", type=int, default=3000, help="env steps whose tiles are "
                        "painted")
    parser.add_argument("--rounds", type=int, default=9, help="rounds of one pass each")
    args = parser.parse_args(argv)
    if args.steps < 1 or args.rounds < 1:
        parser.error("--steps and --rounds must be ≥ 1")
    if args.steps > MAX_STEPS:
        parser.error(f"--steps must be ≤ {MAX_STEPS} (the episodes' tracks and tile lists "
                     "are kept in memory); give fewer steps")
    pin_to_one_core()
    return report("bench_paint.py", lambda: run(args.rev, args.steps, args.rounds,
                                                quiet=args.json),
                  table, args.json, failure=PaintDiffers)


if __name__ == "__main__":
    sys.exit(main())

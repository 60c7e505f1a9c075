"""A scene: shots shot from one track layout, and the one placement that serves them all.

``camtraj place SHOT1 SHOT2 …`` or ``camtraj place --scene SCENE.toml`` searches one placement
for every shot (:func:`camtraj.place.search` over all of them): every shot reachable, then the
largest worst-shot maximum feasible speed, the margins as the tie-break. Where no single
placement serves every shot, the smallest split is proposed: the fewest groups of shots that
each share a placement (searched group by group, the cheap tests ruling out most groups),
unless one of the groups' placements serves every shot after all (the whole scene's search
solves only its finalists on every frame, and can miss it: :func:`serving_everyone`).

The scene file is :mod:`camtraj.scene_file`.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any

from camtraj.errors import InfeasibleError, InputError, PlacementError
from camtraj.inputs import (
    require_regular_files,
)
from camtraj.options import ConvertOptions
from camtraj.place import (
    LIMITS_USE,
    Layout,
    Problem,
    _race,
    _Runner,
    base_height,
    columns,
    heights,
    load_problem,
    passing_screen,
    screen,
    search,
    with_clearance,
)
from camtraj.scene_file import SceneShot, refuse_repeats
from camtraj.set_file import SetFile
from camtraj.shown import speed_percent
from camtraj.workers import default_jobs

MAX_SPLIT_SHOTS = 12
"""Scenes of more shots get no split proposal (the partitions grow too many to try)."""


# ---------------------------------------------------------------------------------------------
# The search and the split
# ---------------------------------------------------------------------------------------------


@dataclass
class SceneReport:
    """What the scene's placement search found.

    ``layout`` is the best single placement for every shot (None when the cheap tests rule
    every one out: ``reason`` says why); ``split`` the smallest split when it does not serve
    every shot: groups of shot indices, each with its placement.
    """

    name: str
    shots: tuple[SceneShot, ...]
    floor_z: float  # [m]; the base stands RAIL_HEIGHT above it (:attr:`base_z`)
    layout: Layout | None
    reason: str
    split: list[tuple[tuple[int, ...], Layout]] | None
    evaluated: int
    screened: int
    seconds: float
    set_file: SetFile
    region: dict[str, Any]

    @property
    def ok(self) -> bool:
        return self.layout is not None and self.layout.ok

    @property
    def base_z(self) -> float:
        """The base's height [m]: on the carriage, on the rail lying on the floor."""
        return base_height(self.floor_z)

    def to_json(self) -> dict[str, Any]:
        return {"layout": self.name, "status": "ok" if self.ok else "split",
                "shots": [s.path for s in self.shots],
                "shot_options": [s.to_json() for s in self.shots], "floor_z": self.floor_z,
                "base_z": self.base_z,
                "placement": None if self.layout is None else self._layout_json(self.layout),
                "reason": self.reason,
                "split": None if self.split is None else [
                    {"shots": [self.shots[i].path for i in group], "indices": list(group),
                     "placement": self._layout_json(lay)} for group, lay in self.split],
                "evaluated": self.evaluated, "screened": self.screened,
                "seconds": self.seconds, "region": self.region}

    def _layout_json(self, lay: Layout) -> dict[str, Any]:
        return {"x": lay.x, "y": lay.y, "yaw_deg": lay.yaw_deg, "ok": lay.ok,
                "limiting_shot": self.shots[lay.limiting].path if lay.results else None,
                "limiting_index": lay.limiting if lay.results else None,
                "shots": [{"shot": self.shots[i].path, "index": i,
                           "camera": self.shots[i].camera, **lay.results[i].to_json()}
                          for i in sorted(lay.results)]}


def place_scene(
    shots: Sequence[SceneShot],
    *,
    name: str,
    robot: str | None = None,
    set_file: str | None = None,
    clearance: float | None = None,
    rate: float = 250.0,
    jobs: int | None = None,
    progress: bool = False,
    lens: str | None = None,
    edges: str = "still",
) -> SceneReport:
    """One placement for every shot of a scene, or the smallest split (module docstring).

    Raises:
        InputError: Unreadable shot, robot or set file; shots on stages of different units.
        PlacementError: A shot that no placement can do even on its own (exit 3).
    """
    from camtraj.convert import load_robot

    start = time.perf_counter()
    jobs = default_jobs(jobs)
    options = [ConvertOptions(robot=robot, set_file=set_file, camera=s.camera, frames=s.frames,
                              clearance=clearance, timing=s.timing, lens=lens, edges=edges)
               for s in shots]
    for s, opt in zip(shots, options, strict=True):
        require_regular_files(s.path, opt)
    refuse_repeats(shots)
    rob = load_robot(options[0])
    sf = SetFile.read(set_file) if set_file is not None else SetFile()
    problems: list[Problem] = []
    units: list[tuple[float, str]] = []
    warned: list[str] = []  # what reading each shot warned of, said with a failure
    for s, opt in zip(shots, options, strict=True):
        problem, shot = load_problem(s.path, opt, rob, sf, clearance=clearance, rate=rate,
                                     timing=s.timing)
        problems.append(problem)
        units.append((shot.meters_per_unit, shot.up_axis))
        warned += [f"{s.name}: {w}" for w in shot.warnings]
    if len(set(units)) > 1:
        seen = ", ".join(f"{s.name} {u[0]:g} m per unit {u[1]}-up"
                         for s, u in zip(shots, units, strict=True))
        msg = f"the shots of a scene must share the stage's units and up axis ({seen})"
        raise InputError(msg)
    mpu, up = units[0]
    everyone = tuple(range(len(shots)))
    runner = _Runner(tuple(problems), jobs, progress)
    try:
        screened = [0]  # candidates of every search's and split test's screen

        def group_search(group: tuple[int, ...]) -> tuple[list[Layout], int, dict[str, Any]]:
            found = search(runner, group, sf, meters_per_unit=mpu, up_axis=up, top=1)
            screened[0] += found[1]
            return found

        # a shot that no placement passes the cheap tests for, even alone, fails the scene
        # before any search (the whole scene's search, then the split's, took 44 s to find
        # what its own cheap tests say in a second: trial 21)
        for i in everyone:
            try:
                passing_screen(runner.problems, (i,), sf, meters_per_unit=mpu, up_axis=up)
            except PlacementError as exc:
                raise PlacementError(_alone(shots[i], str(exc))) from None
        layout: Layout | None = None
        reason = ""
        region: dict[str, Any] = {}
        try:
            layouts, _, region = group_search(everyone)
            layout = layouts[0]
            if not layout.ok:
                bad = layout.results[layout.limiting]
                reason = f"{shots[layout.limiting].name} at the best: {bad.reason}"
        except PlacementError as exc:
            reason = str(exc)
        split = None
        if layout is None or not layout.ok:
            def cheap(group: tuple[int, ...]) -> bool:
                try:
                    scr = screen(runner.problems, group, sf, meters_per_unit=mpu, up_axis=up)
                except PlacementError:
                    return False
                screened[0] += len(scr.grid)
                return bool(scr.ok.any())

            split = smallest_split(len(shots), cheap, lambda g: _best_ok(group_search, g),
                                   known={everyone: None})
            one = None if split is None else serving_everyone(runner, split, everyone)
            if one is not None:  # a group's placement serves the whole scene after all
                layout, reason, split = one, "", None
            elif split is None:
                msg = _no_split(shots, group_search)
                raise PlacementError(msg)
    except InfeasibleError as exc:  # what reading the shots warned of is often why
        exc.shot_warnings = tuple(warned)
        raise
    finally:
        runner.close()
    return SceneReport(name, tuple(shots), problems[0].floor_z, layout, reason, split,
                       runner.count, screened[0], time.perf_counter() - start,
                       with_clearance(sf, clearance), region)


def serving_everyone(runner: Any, split: list[tuple[tuple[int, ...], Layout]],
                     everyone: tuple[int, ...]) -> Layout | None:
    """The best of a split's placements that serves every shot of the scene, or None.

    The whole scene's search races its placements on a subsample of each shot's frames and
    solves only its finalists on every frame, so it can miss a placement that a group's
    search finds: each group's placement (its own shots already solved on every frame) is
    solved for the other shots, best bound first (``runner``: :class:`camtraj.place._Runner`).
    """
    tries = [Layout(lay.x, lay.y, lay.yaw_deg,
                    (*(i for i in everyone if i not in group), *group), dict(lay.results))
             for group, lay in split]
    _race(runner, tries, dict.fromkeys(everyone, 1), 1)
    good = [t for t in tries if t.ok]
    return max(good, key=Layout.rank) if good else None


def _best_ok(group_search: Callable[[tuple[int, ...]], tuple[list[Layout], int, Any]],
             group: tuple[int, ...]) -> Layout | None:
    try:
        best = group_search(group)[0][0]
    except PlacementError:
        return None
    return best if best.ok else None


def _alone(shot: SceneShot, why: str) -> str:
    """Why a scene cannot be placed: one of its shots cannot be, even on its own."""
    return f"{shot.name}: no placement can do it even on its own ({why})"


def _no_split(shots: Sequence[SceneShot],
              group_search: Callable[[tuple[int, ...]], tuple[list[Layout], int, Any]]) -> str:
    """Why no split works: the first shot that no placement can do on its own."""
    for i, s in enumerate(shots):
        try:
            best = group_search((i,))[0][0]
        except PlacementError as exc:
            return _alone(s, str(exc))
        if not best.ok:
            return _alone(s, f"the best: {best.results[i].reason}")
    if len(shots) > MAX_SPLIT_SHOTS:
        return (f"no single layout serves every shot, and a scene of more than "
                f"{MAX_SPLIT_SHOTS} shots gets no split proposal: place it in smaller groups")
    return "no split of the scene found"  # pragma: no cover - singletons always split


def partitions(items: Sequence[int], k: int) -> Iterator[list[tuple[int, ...]]]:
    """Every partition of ``items`` into ``k`` non-empty groups (each group in item order)."""
    n = len(items)
    if k == 1:
        yield [tuple(items)]
        return
    if n == k:
        yield [(i,) for i in items]
        return
    if k < 1 or n < k:
        return
    first, rest = items[0], items[1:]
    for p in partitions(rest, k - 1):
        yield [(first,), *p]
    for p in partitions(rest, k):
        for j in range(len(p)):
            yield [*p[:j], (first, *p[j]), *p[j + 1:]]


def smallest_split(n: int, cheap: Callable[[tuple[int, ...]], bool],
                   serve: Callable[[tuple[int, ...]], Layout | None], *,
                   known: dict[tuple[int, ...], Layout | None] | None = None,
                   ) -> list[tuple[tuple[int, ...], Layout]] | None:
    """The split of shots 0..n-1 into the fewest groups that each share a placement.

    ``cheap(group)`` is a necessary test (some placement passes the cheap tests for every
    shot of the group); ``serve(group)`` the search, a placement that serves the group or None.
    A group that fails either rules out every group that holds it. Partitions are tried by
    the number of groups, two first; the first whose every group is served is returned.
    """
    if n > MAX_SPLIT_SHOTS:
        return None
    served: dict[tuple[int, ...], Layout | None] = dict(known or {})
    passes: dict[tuple[int, ...], bool] = {}
    failed: list[frozenset[int]] = [frozenset(g) for g, lay in served.items() if lay is None]

    def could(group: tuple[int, ...]) -> bool:
        if any(f <= frozenset(group) for f in failed):
            return False
        if group not in passes:
            passes[group] = cheap(group)
            if not passes[group]:
                failed.append(frozenset(group))
        return passes[group]

    def works(group: tuple[int, ...]) -> Layout | None:
        if not could(group):
            return None
        if group not in served:
            served[group] = serve(group)
            if served[group] is None:
                failed.append(frozenset(group))
        return served[group]

    for k in range(2, n + 1):
        for partition in partitions(list(range(n)), k):
            if not all(could(g) for g in partition):
                continue
            found = [works(g) for g in partition]
            if all(lay is not None for lay in found):
                return [(g, lay) for g, lay in zip(partition, found, strict=True)
                        if lay is not None]
    return None


# ---------------------------------------------------------------------------------------------
# For people
# ---------------------------------------------------------------------------------------------

HEADER = ("   # shot                     speed  limits use  wrist  stretch  obstacle  set by")


def _rows(report: SceneReport, lay: Layout) -> list[str]:
    lines = [f"  x {lay.x:.3f} m  y {lay.y:.3f} m  yaw {lay.yaw_deg:.2f} deg", HEADER]
    for i in sorted(lay.results):
        r = lay.results[i]
        name = report.shots[i].name  # numbered: a cut name may hide which file it is
        short = name if len(name) <= 21 else "…" + name[-20:]
        lines.append(f"  {i + 1:>2} {short:<21}  {columns(r)}"
                     + ("  <- limits the layout" if i == lay.limiting and len(lay.order) > 1
                        else ""))
        if not r.ok:
            lines.append(f"     not possible: {r.reason}")
    return lines


def table(report: SceneReport) -> str:
    """The scene's placement per shot, or the split, for people."""
    n = len(report.shots)
    lines = [f"layout {report.name}: {n} shots, {report.evaluated} shot placements solved, "
             f"{report.screened} screened, in {report.seconds:.1f} s "
             f"({heights(report.floor_z, report.base_z)})",
             f"  ({LIMITS_USE}; wrist, stretch: margins; obstacle: closest approach)"]
    if report.ok and report.layout is not None:
        lay = report.layout
        lines += _rows(report, lay)
        lines.append(f"  {report.shots[lay.limiting].name} limits the layout: "
                     f"{speed_percent(lay.results[lay.limiting].max_speed)} of real time")
        return "\n".join(lines)
    lines.append(f"  no single layout serves every shot: {report.reason}")
    if report.split is not None:
        lines.append(f"  the smallest split: {len(report.split)} layouts")
        for k, (group, lay) in enumerate(report.split, 1):
            names = ", ".join(report.shots[i].name for i in group)
            lines.append(f"  layout {k}: {names}")
            lines += ["  " + ln for ln in _rows(report, lay)]
    return "\n".join(lines)


def split_text(report: SceneReport) -> str:
    """The split in one line: ``a.usda, c.usda | b.usda``."""
    assert report.split is not None
    return " | ".join(", ".join(report.shots[i].name for i in group)
                      for group, _ in report.split)

"""``camtraj place``: where to lay the track for one shot (:mod:`camtraj.place`), or one layout
for a scene's shots (:mod:`camtraj.scene`); the command only, so that neither module imports
the other's caller."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import click

from camtraj.choices import TIMING_MODES
from camtraj.options import EDGE_OPTIONS
from camtraj.place import place, table

__all__ = ["place_command"]


@click.command("place", epilog="Exit codes: 0 a placement can do the shot (every shot of a "
               "scene); 2 bad input; 3 no placement can (the reason is printed; for a scene, "
               "the smallest split of its shots into layouts).")
@click.argument("shots", nargs=-1, type=click.Path(), metavar="[SHOT]...")
@click.option("--scene", type=click.Path(), metavar="SCENE.toml",
              help="A scene file listing the shots and each one's camera, frames and timing "
                   "(instead of SHOT...).")
@click.option("--robot", type=click.Path(), metavar="ROBOT.toml",
              help="Robot description file (default: the built-in robot).")
@click.option("--set-file", type=click.Path(), metavar="SET.toml",
              help="Floor height and region, keep-out polygons, yaw range, obstacles.")
@click.option("--camera", metavar="PRIM",
              help="Camera prim path of every shot (default: the only camera).")
@click.option("--frames", metavar="A:B", help="Film frame range of every shot (inclusive).")
@click.option("--clearance", type=click.FloatRange(0.0, 5.0), metavar="M",
              help="Distance [m] to keep from the obstacles (default: the set file's).")
@click.option("--lens", type=click.Path(), metavar="LENS.toml",
              help="Lens file: its zoom, focus and iris motors are timed with the joints, as "
                   "convert --lens times them (default: the robot file's [lens], if any).")
@click.option("--edges", type=click.Choice(EDGE_OPTIONS), default="still", show_default=True,
              help="How the shots will be converted: convert's --edges (still: the robot "
                   "still on an end frame where the camera rests, a slower take).")
@click.option("--timing", type=click.Choice(TIMING_MODES), default=None,
              help="How the shots will be converted: a placement where a shot fits only "
                   "slowed down serves it with scale or optimal (default: shot, each at its own "
                   "timing; with --scene, the scene file gives each shot's).")
@click.option("-j", "--jobs", type=click.IntRange(min=1), default=None,
              help="Worker processes (default: the number of CPUs).")
@click.option("--top", type=click.IntRange(1, 20), default=3, show_default=True,
              help="Placements to list (one shot; a scene lists its best).")
@click.option("--json", "as_json", is_flag=True, help="Print the result as JSON.")
@click.option("-o", "--output", type=click.Path(), metavar="PLACED.toml",
              help="Write the best placement as a set file for convert --set-file (for a "
                   "scene, named by its layout: the scene's name or PLACED's).")
@click.option("-q", "--quiet", is_flag=True, help="No progress bar.")
@click.pass_context
def place_command(ctx: click.Context, /, shots: tuple[str, ...], scene: str | None,
                  robot: str | None, set_file: str | None, camera: str | None,
                  frames: str | None, clearance: float | None, lens: str | None,
                  edges: str, timing: str | None, jobs: int | None, top: int, as_json: bool,
                  output: str | None, quiet: bool) -> None:
    """Find where to lay the track for SHOT: the robot base's x, y and yaw on the floor.

    Prints the best placements (x, y, yaw, maximum feasible speed, the axis that limits it,
    margins) and with -o writes the best as a set file that convert --set-file takes.

    With several shots (or --scene), one layout for all of them: every shot reachable, then
    the largest speed of the slowest shot; per shot its speed, margins and obstacle clearance,
    and which shot limits the layout. Where no single layout serves every shot, the smallest
    split (which shots share a layout) is printed and the exit code is 3.
    """
    import json

    from camtraj.errors import CamtrajError, failure_lines
    from camtraj.inputs import files_read
    from camtraj.options import ConvertOptions, _parse_frames
    from camtraj.outputs import OutputSet
    from camtraj.set_file import to_toml

    if (scene is None) == (not shots):
        raise click.UsageError("give the shots or --scene SCENE.toml (one of them)")
    progress = not quiet and sys.stderr.isatty()
    with OutputSet() as outputs:
        try:
            span = _parse_frames(frames) if frames else None
            layout_name = None
            if scene is not None or len(shots) > 1:
                from camtraj.scene_file import Scene, SceneShot

                if scene is not None:
                    if camera is not None or frames is not None or timing is not None:
                        raise click.UsageError("with --scene, give --camera, --frames and "
                                               "--timing per shot in the scene file")
                    parsed = Scene.read(scene)
                    if parsed.set_file is not None and set_file is not None:
                        raise click.UsageError("the scene file names a set file; give "
                                               "--set-file only without one")
                    set_file = set_file or parsed.set_file
                    members = list(parsed.shots)
                    layout_name = parsed.name or Path(scene).stem
                else:
                    members = [SceneShot(s, camera, span, timing or "shot") for s in shots]
                    layout_name = Path(output).stem if output is not None else "scene"
            if output is not None:  # checked before the search, like every command's outputs
                outputs.add(output, "-o")
                if set_file is not None:  # and the set file can take a new placement
                    from camtraj.set_file import SetFile

                    to_toml(0.0, 0.0, 0.0, 0.0, SetFile.read(set_file).text)
                given = [m.path for m in members] if layout_name is not None else list(shots)
                outputs.refuse_inputs([
                    *files_read(given, ConvertOptions(robot=robot, set_file=set_file,
                                                      lens=lens)),
                    *([] if scene is None else [(Path(scene), "the scene file")])])
            if layout_name is None:
                report = place(shots[0], robot=robot, set_file=set_file, camera=camera,
                               frames=span, clearance=clearance, jobs=jobs,
                               progress=progress, top=top, lens=lens, timing=timing or "shot",
                               edges=edges)
            else:
                _place_scene(ctx, outputs, members, layout_name, robot=robot,
                             set_file=set_file, clearance=clearance, jobs=jobs,
                             progress=progress, as_json=as_json, output=output, lens=lens,
                             edges=edges)
                return
        except CamtrajError as exc:
            for line in failure_lines(exc):
                click.echo(line, err=True)
            ctx.exit(exc.exit_code)
        click.echo(json.dumps(report.to_json(), indent=2) if as_json else table(report))
        best = report.best
        if not best.ok:
            slower = (" (--timing scale takes a placement where it fits slowed down)"
                      if best.reachable == 1.0 and best.collision_free and not best.feasible
                      else "")
            click.echo(f"ERROR: no placement can do the shot as asked; the best: {best.reason}"
                       f"{slower}", err=True)
            ctx.exit(3)
        if output is not None:
            text = to_toml(best.x, best.y, report.base_z, best.yaw_deg, report.set_file.text)
            _write(ctx, outputs, output, text, as_json)


def _write(ctx: click.Context, outputs: Any, output: str, text: str, as_json: bool) -> None:
    from camtraj.errors import CamtrajError, failure_lines

    try:
        outputs.write_bytes(output, text.encode("utf-8"))
        outputs.commit()
    except CamtrajError as exc:
        for line in failure_lines(exc):
            click.echo(line, err=True)
        ctx.exit(exc.exit_code)
    if not as_json:
        click.echo(f"  wrote {output}")


def _place_scene(ctx: click.Context, outputs: Any, members: list[Any], name: str, *,
                 robot: str | None, set_file: str | None, clearance: float | None,
                 jobs: int | None, progress: bool, as_json: bool, output: str | None,
                 lens: str | None = None, edges: str = "still") -> None:
    """``camtraj place`` of a scene: one layout for every shot, or the smallest split."""
    import json

    from camtraj.scene import place_scene, split_text
    from camtraj.scene import table as scene_table
    from camtraj.set_file import to_toml

    report = place_scene(members, name=name, robot=robot, set_file=set_file,
                         clearance=clearance, jobs=jobs, progress=progress, lens=lens,
                         edges=edges)
    click.echo(json.dumps(report.to_json(), indent=2) if as_json else scene_table(report))
    if not report.ok or report.layout is None:
        click.echo(f"ERROR: no single layout serves every shot of the scene; the smallest "
                   f"split: {split_text(report)} (place each group on its own)", err=True)
        ctx.exit(3)
    if output is not None:
        lay = report.layout
        text = to_toml(lay.x, lay.y, report.base_z, lay.yaw_deg, report.set_file.text,
                       layout=name)
        _write(ctx, outputs, output, text, as_json)

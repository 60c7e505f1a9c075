"""The README's example outputs are what camtraj prints (tests/readme_examples.py runs them)."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.readme_examples import (
    DOCUMENTS,
    REGENERATE,
    Block,
    ExampleError,
    agrees,
    blocks,
    diff,
    run_block,
)

EXAMPLES = [b for d in DOCUMENTS for b in blocks(d)]


def test_the_readme_has_examples() -> None:
    assert len(EXAMPLES) >= 3
    assert all(b.commands for b in EXAMPLES)
    # the whip's two blocks carry <!-- round-off: 5% --> (a move faster than the robot)
    loose = [b for b in EXAMPLES if b.rtol != 0.01]
    assert len(loose) == 2 and all(b.rtol == 0.05 and "whip_pan" in b.text for b in loose)
    # place's says how long its search took
    timed = [b for b in EXAMPLES if b.clock]
    assert len(timed) == 1 and timed[0].commands[0].startswith("camtraj place")


@pytest.mark.parametrize("block", EXAMPLES, ids=[b.name for b in EXAMPLES])
def test_example_output_is_what_camtraj_prints(block: Block, tmp_path: Path) -> None:
    got = run_block(block, tmp_path)
    if not agrees(block.text, got, block.rtol, block.clock):
        pytest.fail(
            f"the README example at {block.name} differs from what camtraj prints now (a solver "
            f"change moves numbers): run `{REGENERATE}` to rewrite every example, read the diff, "
            f"and fix any prose around it that no longer holds\n{diff(block, got)}", pytrace=False)


def test_a_changed_output_is_found_and_rewritten(tmp_path: Path) -> None:
    """The mechanism itself: a stale number is a difference, and --write puts the real one."""
    from tests import readme_examples

    doc = tmp_path / "DOC.md"
    stale = "$ camtraj check samples/shots/maya_dolly_push_in.usda --frames 1001:1010\n"
    doc.write_text(f"Text.\n\n```console\n{stale}{{}}\n```\n\nMore text.\n", encoding="utf-8")
    (block,) = blocks(doc)
    work = tmp_path / "run"
    work.mkdir()
    real = run_block(block, work)
    assert real.startswith(stale) and ": FEASIBLE at shot timing" in real
    assert readme_examples.check((doc,)) != []
    # ``check`` names blocks relative to the repository; a document elsewhere is fine to rewrite
    assert readme_examples.check((doc,), write=True)
    assert doc.read_text(encoding="utf-8") == f"Text.\n\n```console\n{real}```\n\nMore text.\n"
    assert readme_examples.check((doc,)) == []


def test_only_camtraj_commands_run(tmp_path: Path) -> None:
    doc = tmp_path / "DOC.md"
    doc.write_text("```console\n$ rm -rf out\n```\n", encoding="utf-8")
    with pytest.raises(ExampleError, match="only camtraj commands"):
        run_block(blocks(doc)[0], tmp_path)


def test_round_off_agrees_and_a_real_change_does_not() -> None:
    """Another CPU's round-off moves a printed number by a unit of its last digit or a
    fraction of a percent (the whip sample under AVX2 kernels); a changed result, word or
    line is still a difference."""
    line = "  elbow      71%      29%     85%    67%    26.636   35.941\n"
    assert agrees(line, "  elbow      71%      29%     85%    68%    26.690   36.027\n")
    assert agrees("speed factor 3.952\n", "speed factor 3.953\n")
    assert not agrees("speed factor 3.952\n", "speed factor 3.992\n")  # 1%: a real change
    assert not agrees("maximum feasible speed 350%\n", "maximum feasible speed 340%\n")
    assert not agrees("frames 16-24\n", "frames 16-26\n")
    assert agrees("pan acceleration 7802 deg/s^2 on frames 16-24\n",
                  "pan acceleration 7808 deg/s^2 on frames 16-24\n")
    # frames, counts and exit codes are not measurements: off by one is a real change
    assert not agrees("frames 16-24\n", "frames 16-25\n")
    assert not agrees("18 frame(s) cannot be reached (frames 29-46); worst: frame 30\n",
                      "19 frame(s) cannot be reached (frames 29-47); worst: frame 31\n")
    assert not agrees("frames 1001-1120 (120 at 24 fps)\n", "frames 1010-1131 (121 at 24 fps)\n")
    assert not agrees("exit 2\n", "exit 3\n")
    assert not agrees("(120 at 24 fps), servo 240 Hz\n", "(120 at 25 fps), servo 240 Hz\n")
    assert not agrees("servo 240 Hz\n", "servo 242 Hz\n")
    assert not agrees("timing shot: take\n", "timing scale: take\n")
    assert not agrees("margin 2.5 deg\n", "margin 2.5 deg (frame 3)\n")
    assert not agrees("a\nb\n", "a\n")
    assert agrees("-0.001 m\n", "0.000 m\n")  # the sign of a rounded zero
    # a block marked <!-- round-off: 5% --> (a move faster than the robot)
    assert agrees("elbow 85%  67%  26.636\n", "elbow 85%  69%  26.798\n", 0.05)
    assert not agrees("elbow 85%  67%  26.636\n", "elbow 85%  69%  26.798\n")
    assert not agrees("frames 16-24\n", "frames 16-25\n", 0.05)
    # a block marked <!-- clock -->: how long the search took is the machine's
    timed = "x.usda: 59 placements solved, 37392 screened, in 11.5 s (floor z 0.000 m)\n"
    later = "x.usda: 59 placements solved, 37392 screened, in 21.1 s (floor z 0.000 m)\n"
    assert agrees(timed, later, clock=True) and not agrees(timed, later)
    assert not agrees(timed, later.replace("59", "58"), clock=True)
    assert not agrees("speed 3.5 s\n", "speed 4.5 s\n", clock=True)  # only after "in "



def test_the_block_markers_read_alone_and_together(tmp_path: Path) -> None:
    """Review 56: '<!-- round-off: 5%; clock -->' lost its clock (' clock' after the split)."""
    doc = tmp_path / "DOC.md"
    fence = "```console\n$ camtraj --version\n```\n\n"
    doc.write_text("".join(f"{m}\n{fence}" for m in (
        "<!-- round-off: 5%; clock -->", "<!-- clock -->", "<!-- round-off: 2% -->", "")),
        encoding="utf-8")
    assert [(b.rtol, b.clock) for b in blocks(doc)] == [
        (0.05, True), (0.01, True), (0.02, False), (0.01, False)]

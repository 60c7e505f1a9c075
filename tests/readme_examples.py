"""The README's example outputs, from real runs: find them, run them, compare or rewrite them.

Every ```console block of README.md and pipelines/README.md is a transcript: lines starting
with ``$ camtraj`` are commands, the lines after each are its output (stdout and stderr, as a
terminal shows them). This script runs every command in a temporary folder in which
``samples`` is the repository's sample folder (so ``samples/shots/...`` reads the shipped
shots and ``out/...`` is written there), with ``camtraj`` meaning this interpreter's
``-m camtraj``, and

    python tests/readme_examples.py            # prints a diff per block that differs; exit 1
    python tests/readme_examples.py --write    # rewrites the blocks with what the runs print
                                               # (what `make readme` does)

``tests/test_readme.py`` fails while any block differs by more than round-off
(:func:`agrees`). A console block holds only camtraj commands (anything else is shown in an
```sh block, which is not run), and no output that depends on the machine or the clock: keep
such lines (elapsed times) out of the examples.

Round-off: the same shot solved on another CPU (other BLAS kernels, other SIMD maths in numpy
and libm) gives a joint path that differs by about the refinement's own tolerance, a
thousandth, and a number printed to four digits can move in its last one (under AVX2
instead of AVX-512 kernels, the whip sample's elbow margin 26.636 -> 26.690 deg). A measured
number (one with decimals, or a whole number with a unit after it but fps or Hz, which are
settings: 72%, 7807 deg/s^2) may
differ by one unit of its last printed digit or by :data:`NUMBER_RTOL` of itself; a bare
whole number (a frame, a count, an exit code) may not, nor may the words between numbers or
how many there are. A block of a move faster than the robot can move more: the axes that do
not limit its speed settle where the refinement's tolerance leaves them, and another CPU's
round-off can pick another of two nearly equally fast answers (the whip under SSE-only
kernels: the elbow's jerk use 67% -> 69%). Such a block says how far, in a comment on the line
before its fence: ``<!-- round-off: 5% -->``. A block whose command says how long it took
(``camtraj place``: "in 11.5 s") says so there too, ``<!-- clock -->`` (both:
``<!-- round-off: 5%; clock -->``): a duration after "in " is the clock's, not compared.
"""

from __future__ import annotations

import difflib
import os
import re
import shlex
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DOCUMENTS = (ROOT / "README.md", ROOT / "pipelines" / "README.md")
REGENERATE = "make readme"
"""How to bring the examples up to date (the command the test's failure message names)."""

_FENCE = re.compile(r"^(?:<!-- ([^>]*) -->\n)?```console\n(.*?)^```\n", re.MULTILINE | re.DOTALL)
_ROUND_OFF = re.compile(r"round-off: (\d+(?:\.\d+)?)%")
_CLOCK = re.compile(r"\bin $")  # a number after this, with " s" after it, is an elapsed time
PROMPT = "$ "


NUMBER_RTOL = 0.01
"""How far a printed number may move with the machine's round-off (:func:`agrees`)."""


class ExampleError(Exception):
    """A console block that cannot be run as an example (it names the file and line)."""


@dataclass(frozen=True)
class Block:
    """One ```console block: where its text is in the document, and its text."""

    document: Path
    start: int  # offset of the block's first line in the document
    end: int
    text: str
    rtol: float = NUMBER_RTOL  # how far a measured number may move (:func:`agrees`)
    clock: bool = False  # its output says how long a command took (:func:`agrees`)

    @property
    def line(self) -> int:
        return self.document.read_text(encoding="utf-8").count("\n", 0, self.start) + 1

    @property
    def commands(self) -> list[str]:
        return [ln[len(PROMPT):] for ln in self.text.splitlines() if ln.startswith(PROMPT)]

    @property
    def name(self) -> str:
        doc = self.document
        return f"{doc.relative_to(ROOT) if doc.is_relative_to(ROOT) else doc}:{self.line}"


def blocks(document: Path) -> list[Block]:
    """The console blocks of ``document``, in order."""
    text = document.read_text(encoding="utf-8")
    out = []
    for m in _FENCE.finditer(text):
        note = m.group(1) or ""
        rtol = _ROUND_OFF.search(note)
        out.append(Block(document, m.start(2), m.end(2), m.group(2),
                         NUMBER_RTOL if rtol is None else float(rtol.group(1)) / 100.0,
                         "clock" in (part.strip() for part in note.split(";"))))
    return out


def _argv(command: str, where: str) -> list[str]:
    words = shlex.split(command, comments=True)
    if not words or words[0] != "camtraj":
        raise ExampleError(f"{where}: a console block runs only camtraj commands, not {command!r}"
                           " (show other commands in an ```sh block)")
    return [sys.executable, "-m", "camtraj", *words[1:]]


def run_block(block: Block, work: Path) -> str:
    """The transcript the block's commands print when run in ``work`` (one folder per block)."""
    if not block.commands:
        raise ExampleError(f"{block.name}: a console block with no '$ camtraj' command")
    samples = work / "samples"
    if not samples.exists():
        samples.symlink_to(ROOT / "samples", target_is_directory=True)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        p for p in (str(ROOT), os.environ.get("PYTHONPATH", "")) if p),
        "PYTHONUNBUFFERED": "1", "COLUMNS": "100"}
    out = []
    for command in block.commands:
        proc = subprocess.run(_argv(command, block.name), cwd=work, env=env, text=True,
                              stdout=subprocess.PIPE, stderr=subprocess.STDOUT, check=False,
                              timeout=600)
        out.append(PROMPT + command + "\n")
        out.append(proc.stdout if proc.stdout.endswith("\n") or not proc.stdout
                   else proc.stdout + "\n")
    return "".join(out).replace(str(work) + os.sep, "")


_NUMBER = re.compile(r"-?\d+(?:\.(\d+))?")
_UNIT_AFTER = re.compile(r" ?(?:%|x\b|m\b|mm\b|deg|s\b|ms\b|µ)")  # not fps, Hz: settings


def agrees(expected: str, got: str, rtol: float = NUMBER_RTOL, clock: bool = False) -> bool:
    """Whether a transcript is the expected one up to round-off: the same lines and words,
    each measured number within one unit of its last printed digit or :data:`NUMBER_RTOL` of
    it, every bare whole number the same; with ``clock``, a duration after "in " any value."""
    if expected == got:
        return True
    old, new = expected.splitlines(), got.splitlines()
    if len(old) != len(new):
        return False
    for a, b in zip(old, new, strict=True):
        if a == b:
            continue
        if _NUMBER.split(a)[::2] != _NUMBER.split(b)[::2]:  # the words around the numbers
            return False
        xs, ys = list(_NUMBER.finditer(a)), list(_NUMBER.finditer(b))
        if len(xs) != len(ys):
            return False
        for x, y in zip(xs, ys, strict=True):
            if (clock and _CLOCK.search(a, 0, x.start())
                    and a.startswith(" s", x.end()) and b.startswith(" s", y.end())):
                continue  # how long it took: the machine's, not camtraj's
            measured = x.group(1) is not None or _UNIT_AFTER.match(a, x.end()) is not None
            if not measured:
                if x.group(0) != y.group(0):  # a frame number, a count: exactly
                    return False
                continue
            unit = 10.0 ** -max(len(x.group(1) or ""), len(y.group(1) or ""))
            u, v = float(x.group(0)), float(y.group(0))
            if abs(u - v) > max(unit * (1 + 1e-9), rtol * abs(u)):
                return False
    return True


def diff(block: Block, got: str) -> str:
    """A unified diff from the block as the README has it to ``got``."""
    return "".join(difflib.unified_diff(
        block.text.splitlines(keepends=True), got.splitlines(keepends=True),
        f"{block.name} (README)", f"{block.name} (what camtraj prints now)"))


def check(documents: tuple[Path, ...] = DOCUMENTS, *, write: bool = False) -> list[str]:
    """Run every example; return a unified diff per block that differs beyond round-off
    (:func:`agrees`), or with ``write`` per block that differs at all, rewritten."""
    diffs = []
    for document in documents:
        found = blocks(document)
        text = document.read_text(encoding="utf-8")
        here = []
        for block in reversed(found):  # rewriting from the end keeps earlier offsets valid
            with tempfile.TemporaryDirectory(prefix="camtraj-readme-") as work:
                got = run_block(block, Path(work))
            if got == block.text or (not write and agrees(block.text, got, block.rtol,
                                                          block.clock)):
                continue
            here.append(diff(block, got))
            text = text[:block.start] + got + text[block.end:]
        if write:
            document.write_text(text, encoding="utf-8")
        diffs += reversed(here)
    return diffs


def main(argv: list[str]) -> int:
    write = "--write" in argv
    diffs = check(write=write)
    for diff in diffs:
        print(diff)
    if write:
        print(f"{len(diffs)} example block(s) rewritten")
        return 0
    if diffs:
        print(f"{len(diffs)} README example(s) differ from what camtraj prints; "
              f"run `{REGENERATE}` to rewrite them, then read the diff before committing")
    return 1 if diffs else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

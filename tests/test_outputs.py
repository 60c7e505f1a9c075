"""The output set (camtraj.outputs): checked up front, committed all or nothing, no leftovers."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from camtraj import outputs as outputs_mod
from camtraj.errors import InputError
from camtraj.outputs import TEMP_MARK, OutputSet, remove_stale_temps, temp_name

OLD_A, OLD_B = b"earlier result A\n", b"earlier result B\n"


def _dead_pid() -> int:
    """The pid of a process that has exited (and been reaped)."""
    proc = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True, check=True)
    return int(proc.stdout)


def _names(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


def test_both_outputs_are_replaced_together(tmp_path: Path) -> None:
    a, b = tmp_path / "a.mcap", tmp_path / "b.json"
    a.write_bytes(OLD_A)
    with OutputSet() as out:
        out.add(a, "-o")
        out.add(b, "--summary")
        with out.open(a) as f:
            f.write(b"new A")
        out.write_bytes(b, b"new B")
        assert a.read_bytes() == OLD_A and not b.exists()  # nothing visible before commit
        assert _names(tmp_path) == ["a.mcap"]  # unnamed temporary files
        out.commit()
    assert (a.read_bytes(), b.read_bytes()) == (b"new A", b"new B")
    assert _names(tmp_path) == ["a.mcap", "b.json"]


def test_error_before_commit_replaces_nothing(tmp_path: Path) -> None:
    a, b = tmp_path / "a.mcap", tmp_path / "b.json"
    a.write_bytes(OLD_A)
    b.write_bytes(OLD_B)

    def run() -> None:
        with OutputSet() as out:
            out.add(a, "-o")
            out.add(b, "--summary")
            out.write_bytes(a, b"new A")
            raise RuntimeError("solver broke")

    with pytest.raises(RuntimeError, match="solver broke"):
        run()
    assert (a.read_bytes(), b.read_bytes()) == (OLD_A, OLD_B)
    assert _names(tmp_path) == ["a.mcap", "b.json"]


def test_failed_second_rename_restores_the_first(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    a, b, fresh = tmp_path / "a.mcap", tmp_path / "b.json", tmp_path / "c.json"
    a.write_bytes(OLD_A)
    b.write_bytes(OLD_B)
    real_replace = os.replace
    calls: list[str] = []

    def replace(src: str | os.PathLike[str], dst: str | os.PathLike[str]) -> None:
        calls.append(os.fspath(dst))
        if os.fspath(dst) == str(b):  # the second output's rename fails (fault injection)
            raise OSError(5, "Input/output error")
        real_replace(src, dst)

    monkeypatch.setattr(outputs_mod.os, "replace", replace)

    def run(paths: list[Path]) -> None:
        with OutputSet() as out:
            for p in paths:
                out.add(p)
                out.write_bytes(p, b"new")
            out.commit()

    for paths in ([a, b], [fresh, b]):
        with pytest.raises(InputError, match=r"b\.json: input/output error; nothing was"):
            run(paths)
    assert (a.read_bytes(), b.read_bytes()) == (OLD_A, OLD_B)
    assert not fresh.exists()  # it did not exist before: removed again
    assert _names(tmp_path) == ["a.mcap", "b.json"]
    assert str(a) in calls  # the first rename did happen, and was undone


@pytest.mark.parametrize("device", ["/dev/null", "/dev/full"])
def test_device_is_refused_and_never_replaced(device: str) -> None:
    before = os.stat(device)
    with pytest.raises(InputError, match="character device, not a regular file"):
        OutputSet().add(device, "-o")
    after = os.stat(device)
    assert (after.st_ino, after.st_rdev, after.st_mode) == (
        before.st_ino, before.st_rdev, before.st_mode)


def test_fifo_and_folder_are_refused(tmp_path: Path) -> None:
    os.mkfifo(tmp_path / "pipe")
    with pytest.raises(InputError, match="named pipe"):
        OutputSet().add(tmp_path / "pipe")
    (tmp_path / "d").mkdir()
    with pytest.raises(InputError, match="a folder, not a regular file"):
        OutputSet().add(tmp_path / "d")


def test_same_file_twice_is_refused(tmp_path: Path) -> None:
    (tmp_path / "sub").mkdir()
    (tmp_path / "x").write_bytes(OLD_A)
    os.link(tmp_path / "x", tmp_path / "hard")
    os.symlink(tmp_path / "x", tmp_path / "soft")
    for other in ("sub/../x", "hard", "soft"):
        out = OutputSet()
        out.add(tmp_path / "x", "-o")
        with pytest.raises(InputError, match="same file as -o"):
            out.add(tmp_path / other, "--summary")
        out.discard()
    out = OutputSet()
    out.add(tmp_path / "new.json", "-o")  # not there yet: compared by resolved path
    with pytest.raises(InputError, match="same file"):
        out.add(tmp_path / "sub" / ".." / "new.json", "--summary")
    out.discard()


def test_inputs_are_refused_through_links(tmp_path: Path) -> None:
    shot = tmp_path / "shot.usda"
    shot.write_bytes(b"#usda 1.0\n")
    os.link(shot, tmp_path / "hard.usda")
    os.symlink(shot, tmp_path / "soft.usda")
    (tmp_path / "sub").mkdir()
    for alias in ("shot.usda", "hard.usda", "soft.usda", "sub/../shot.usda"):
        out = OutputSet()
        out.add(tmp_path / alias, "-o")
        with pytest.raises(InputError, match=r"refusing to write -o .*: it is the shot"):
            out.refuse_inputs([(shot, "the shot")])
        out.discard()
    assert shot.read_bytes() == b"#usda 1.0\n"


def test_write_through_a_symlink_keeps_the_link(tmp_path: Path) -> None:
    (tmp_path / "real.mcap").write_bytes(OLD_A)
    os.symlink("real.mcap", tmp_path / "link.mcap")
    with OutputSet() as out:
        out.add(tmp_path / "link.mcap")
        out.write_bytes(tmp_path / "link.mcap", b"new")
        out.commit()
    assert (tmp_path / "link.mcap").is_symlink()
    assert (tmp_path / "real.mcap").read_bytes() == b"new"


def test_missing_folders_are_made_and_removed_again_when_nothing_is_written(
    tmp_path: Path,
) -> None:
    with OutputSet() as outputs:
        outputs.add(tmp_path / "new" / "deeper" / "x.mcap", "-o")
        assert (tmp_path / "new" / "deeper").is_dir()
    assert list(tmp_path.iterdir()) == []  # the run wrote nothing: no empty folders either
    # a second output deeper in the first's new folder (-o a/x.mcap --summary a/b/x.json):
    # its folder is removed before the first's (a new user found a/ left behind)
    with OutputSet() as outputs:
        outputs.add(tmp_path / "a" / "x.mcap", "-o")
        outputs.add(tmp_path / "a" / "b" / "x.json", "--summary")
        outputs.add(tmp_path / "c" / "x.html", "--report")
    assert list(tmp_path.iterdir()) == []
    with OutputSet() as outputs:
        outputs.add(tmp_path / "new" / "x.mcap", "-o")
        outputs.write_bytes(tmp_path / "new" / "x.mcap", b"data")
        outputs.commit()
    assert (tmp_path / "new" / "x.mcap").read_bytes() == b"data"
    (tmp_path / "file").write_bytes(b"")
    with pytest.raises(InputError, match=r"file is a file, not a folder"):
        OutputSet().add(tmp_path / "file" / "x.mcap", "-o")
    with pytest.raises(InputError, match=r"file is a file, not a folder"):
        OutputSet().add(tmp_path / "file" / "sub" / "x.mcap", "-o")


def test_stale_temporary_files_of_gone_processes_are_removed(tmp_path: Path) -> None:
    dead = _dead_pid()
    mine = temp_name("x.mcap")
    host = mine.split(TEMP_MARK)[1].rsplit("-", 1)[0]
    stale = tmp_path / f".x.mcap{TEMP_MARK}{host}-{dead}"
    stale_backup = tmp_path / f".x.mcap.camtraj-old-{host}-{dead}"
    other_host = tmp_path / f".x.mcap{TEMP_MARK}someotherhost-{dead}"
    alive = tmp_path / f".x.mcap{TEMP_MARK}{host}-1"  # pid 1 is always running
    other_name = tmp_path / f".y.mcap{TEMP_MARK}{host}-{dead}"
    for p in (stale, stale_backup, other_host, alive, other_name):
        p.write_bytes(b"partial")
    with OutputSet() as out:  # adding x.mcap cleans x.mcap's stale files only
        out.add(tmp_path / "x.mcap")
    assert not stale.exists() and not stale_backup.exists()
    assert other_host.exists() and alive.exists() and other_name.exists()
    assert remove_stale_temps(tmp_path) == [other_name]


def test_named_temporary_files_when_unnamed_ones_are_unsupported(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.delattr(outputs_mod.os, "O_TMPFILE", raising=False)
    target = tmp_path / "x.mcap"
    seen: list[list[str]] = []

    def run() -> None:
        with OutputSet() as out:
            out.add(target)
            out.write_bytes(target, b"partial")
            seen.append(_names(tmp_path))
            raise RuntimeError

    with pytest.raises(RuntimeError):
        run()
    assert seen == [[temp_name("x.mcap")]]
    assert _names(tmp_path) == []
    with OutputSet() as out:
        out.add(target)
        out.write_bytes(target, b"done")
        out.commit()
    assert _names(tmp_path) == ["x.mcap"]


def test_a_write_error_part_way_replaces_nothing(tmp_path: Path) -> None:
    """A full disk, simulated with a file size limit (writes past it fail with EFBIG)."""
    target = tmp_path / "x.mcap"
    target.write_bytes(OLD_A)
    code = f"""
import resource, sys
from camtraj.outputs import OutputSet
from camtraj.errors import InputError
resource.setrlimit(resource.RLIMIT_FSIZE, (4096, 4096))
try:
    with OutputSet() as out:
        out.add({str(target)!r}, "-o")
        out.write_bytes({str(target)!r}, b"x" * 100000)
        out.commit()
except InputError as exc:
    print(exc)
    sys.exit(2)
"""
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=False)
    assert proc.returncode == 2, proc.stderr
    assert "cannot write -o" in proc.stdout and "too large" in proc.stdout
    assert target.read_bytes() == OLD_A
    assert _names(tmp_path) == ["x.mcap"]


def test_batch_removes_stale_temporary_files_in_its_folder(tmp_path: Path) -> None:
    from camtraj.batch import REPORT_NAME, run_batch
    from camtraj.options import ConvertOptions

    host = temp_name("x").split(TEMP_MARK)[1].rsplit("-", 1)[0]
    stale = tmp_path / f".a.mcap{TEMP_MARK}{host}-{_dead_pid()}"
    stale.write_bytes(b"partial take of a cancelled task")
    report = run_batch([str(tmp_path / "missing.usda")], tmp_path, options=ConvertOptions())
    assert report.exit_code == 2
    assert _names(tmp_path) == [REPORT_NAME]


_KILLED_IN_COMMIT = """
import os, signal, sys
from camtraj import outputs
folder, at = sys.argv[1], int(sys.argv[2])
calls = 0
def killing(real):
    def call(*args, **kwargs):
        global calls
        calls += 1
        if calls == at:
            os.kill(os.getpid(), signal.SIGKILL)
        return real(*args, **kwargs)
    return call
names = ["a.mcap", "b.json", "c.usda"]
out = outputs.OutputSet()
for name in names:
    out.add(os.path.join(folder, name))
    out.write_bytes(os.path.join(folder, name), b"new " + name.encode())
for name in ("link", "replace", "unlink"):  # every file system call of the commit
    setattr(outputs.os, name, killing(getattr(os, name)))
out.commit()
print(calls)
"""


@pytest.mark.parametrize("existing", [(), ("b.json",)])
def test_sigkill_inside_the_commit(tmp_path: Path, existing: tuple[str, ...]) -> None:
    """SIGKILL at each file system call of the commit (issue 14, §4): outputs that did not
    exist are linked straight into place, so with no earlier file nothing else is ever left;
    an output replacing a file may leave its ``-tmp-``/``-old-`` names, which the next run
    writing it removes."""
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).parents[1])}
    at = 1
    while True:
        folder = tmp_path / f"k{at}"
        folder.mkdir()
        for name in existing:
            (folder / name).write_bytes(b"old")
        proc = subprocess.run([sys.executable, "-c", _KILLED_IN_COMMIT, str(folder), str(at)],
                              capture_output=True, env=env, check=False)
        left = sorted(p.name for p in folder.iterdir())
        if proc.returncode == 0:  # fewer calls than ``at``: all of them were tried
            assert left == ["a.mcap", "b.json", "c.usda"]
            break
        assert proc.returncode == -9, proc.stderr
        finals = [n for n in left if not n.startswith(".")]
        assert set(finals) <= {"a.mcap", "b.json", "c.usda"}
        for name in finals:
            assert (folder / name).read_bytes() in (b"old", b"new " + name.encode())
        stale = [n for n in left if n.startswith(".")]
        if not existing:
            assert stale == [], at
        assert all(n.startswith(".b.json.camtraj-") for n in stale), stale
        with OutputSet() as again:  # the next run writing b.json
            again.add(folder / "b.json")
        assert [p.name for p in folder.iterdir() if p.name.startswith(".")] == []
        at += 1
    assert at > 3


def test_a_folder_made_read_only_before_the_commit_is_said_once(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Trial 21: the folder made read-only during a run read "cannot write -o p.toml: cannot
    write -o p.toml: permission denied"; the output is named once."""
    def refused(*_args: object, **_kwargs: object) -> None:
        raise PermissionError(13, "Permission denied")

    target = tmp_path / "p.toml"
    with OutputSet() as out:
        out.add(target, "-o")
        out.write_bytes(target, b"x = 1\n")
        monkeypatch.setattr(outputs_mod.os, "link", refused)  # an unnamed temporary file
        monkeypatch.setattr(outputs_mod.os, "replace", refused)  # a named one (no O_TMPFILE)
        with pytest.raises(InputError) as err:
            out.commit()
    assert str(err.value).count("cannot write") == 1, err.value
    assert str(err.value).endswith("permission denied; nothing was replaced"), err.value
    assert not target.exists()

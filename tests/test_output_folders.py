"""No user file is ever changed or removed by an output: property-based over
random trees of user files (every command's folder goes through
io/outputs.building_folder), plus the examples of each command."""

import os
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from dvrk_dart.cli import main
from dvrk_dart.errors import DvrkDartError
from dvrk_dart.io.outputs import MARKER, building_folder, read_marker

NAME = st.text(alphabet="abcXYZ_- é0.", min_size=1, max_size=8).filter(lambda n: n not in (".", "..") and n != MARKER)
TOOL_FILES = ("index.html", "figures/plot.png", "analysis/metrics.csv")


@st.composite
def user_trees(draw):
    """{relative path: bytes}, nested up to three levels, some inside the tool's own sub-folders."""
    files = {}
    for _ in range(draw(st.integers(1, 6))):
        parts = draw(st.lists(NAME, min_size=0, max_size=2))
        if draw(st.booleans()):
            parts = [draw(st.sampled_from(["figures", "analysis"])), *parts]
        files["/".join([*parts, draw(NAME)])] = draw(st.binary(max_size=64))
    # no file may be the folder of another
    names = sorted(files)
    return {n: files[n] for n in names if not any(other.startswith(n + "/") for other in names)}


def _write_tree(folder: Path, tree: dict[str, bytes]) -> None:
    for relative, content in tree.items():
        (folder / relative).parent.mkdir(parents=True, exist_ok=True)
        (folder / relative).write_bytes(content)


def _snapshot(folder: Path) -> dict[str, bytes]:
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in folder.rglob("*") if p.is_file() and not p.is_symlink()}


def _build(target: Path, version: bytes) -> None:
    with building_folder(target, "report") as folder:
        _write_tree(folder, {name: version for name in TOOL_FILES})


settings_ = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])


@settings_
@given(tree=user_trees())
def test_an_unmarked_folder_is_refused_and_left_as_it_was(tmp_path_factory, tree):
    target = tmp_path_factory.mktemp("out") / "site"
    _write_tree(target, tree)
    before = _snapshot(target)
    with pytest.raises(DvrkDartError, match="not made by dvrk-dart"):
        _build(target, b"new")
    assert _snapshot(target) == before
    assert not list(target.parent.glob(".site.*"))


@settings_
@given(tree=user_trees())
def test_a_marked_folder_keeps_the_user_files_put_in_it(tmp_path_factory, tree):
    """The tool's files are replaced, the user's kept byte for byte at their
    place; where the user's file takes a name the tool writes, nothing changes."""
    target = tmp_path_factory.mktemp("out") / "site"
    _build(target, b"old")
    clash = any(relative in TOOL_FILES for relative in tree) or any(
        tool.startswith(relative + "/") or relative.startswith(tool + "/") for relative in tree for tool in TOOL_FILES)
    for relative in list(tree):
        if (target / relative).exists():
            del tree[relative]  # the tool's own file: a user editing it is covered below
    try:
        _write_tree(target, tree)
    except (NotADirectoryError, FileExistsError, IsADirectoryError):
        return  # the tree cannot coexist with the tool's files
    before = _snapshot(target)
    if clash:
        with pytest.raises(DvrkDartError):
            _build(target, b"new")
        assert _snapshot(target) == before
        return
    _build(target, b"new")
    after = _snapshot(target)
    for relative, content in tree.items():
        assert after[relative] == content, relative
    for name in TOOL_FILES:
        assert after[name] == b"new"
    assert set(read_marker(target).files) == set(TOOL_FILES)


def test_a_symlink_the_user_put_in_a_marked_folder_is_kept(tmp_path):
    target = tmp_path / "site"
    _build(target, b"old")
    outside = tmp_path / "precious.txt"
    outside.write_text("keep")
    os.symlink(outside, target / "link")
    _build(target, b"new")
    assert (target / "link").is_symlink() and (target / "link").read_text() == "keep"


def test_half_built_folders_of_dead_processes_are_removed(tmp_path):
    target = tmp_path / "site"
    from dvrk_dart.io.outputs import BUILDING_SENTINEL

    stale = tmp_path / ".site.building-999999999-deadbeef"
    stale.mkdir()
    (stale / BUILDING_SENTINEL).touch()
    (stale / "index.html").write_text("half")
    live = tmp_path / f".site.building-{os.getppid()}-cafebabe"
    live.mkdir()
    (live / BUILDING_SENTINEL).touch()
    users = tmp_path / ".site.building-999999999-mine"  # a user's folder of a like name, no sentinel
    users.mkdir()
    (users / "important.txt").write_text("mine")
    _build(target, b"new")
    assert not stale.exists() and live.exists() and (users / "important.txt").read_text() == "mine"


def test_an_empty_user_folder_is_carried(tmp_path):
    target = tmp_path / "site"
    _build(target, b"old")
    (target / "keepme").mkdir()
    _build(target, b"new")
    assert (target / "keepme").is_dir()


def test_a_marker_proves_nothing_about_files_changed_since(tmp_path):
    """A forged or copied marker, or a file the user edited after the run: the
    checksum differs, so the file is the user's and is never replaced."""
    target = tmp_path / "id"
    _build(target, b"tool")
    (target / "index.html").write_text("edited by the user")
    built = []
    with pytest.raises(DvrkDartError, match="changed since"):  # before any work: the new output may write that file
        with building_folder(target, "report") as folder:
            built.append(folder)
    assert not built and (target / "index.html").read_text() == "edited by the user"


def test_an_earlier_versions_marker_is_not_trusted(tmp_path):
    target = tmp_path / "id"
    target.mkdir()
    (target / MARKER).write_text("identification\n")
    (target / "params.json").write_text("mine")
    with pytest.raises(DvrkDartError, match="not made by dvrk-dart"):
        with building_folder(target, "identification"):
            pass
    assert (target / "params.json").read_text() == "mine"


def test_a_symbolic_link_as_out_is_refused(tmp_path):
    real = tmp_path / "real"
    _build(real, b"tool")
    (real / "notes.txt").write_text("mine")
    link = tmp_path / "link"
    link.symlink_to(real)
    with pytest.raises(DvrkDartError, match="symbolic link"):
        with building_folder(link, "report"):
            pass
    assert link.is_symlink() and (real / "notes.txt").read_text() == "mine"


@pytest.mark.parametrize("args, user_file", [
    (["identify", "--runs", "one", "--processing", "upstream"], "params.json"),
    (["diagnose", "--measured", "two"], "figures/my_plot.png"),
    (["uncertainty", "--measured", "two", "--samples", "2", "--duration", "0.5"], "params/my.json"),
    (["replay", "--measured", "two", "--duration", "0.2"], "config.json"),
    (["excitation", "two"], "excitation.json"),
])
def test_every_command_refuses_a_user_folder(tmp_path, capsys, args, user_file):
    out = tmp_path / "lab"
    (out / user_file).parent.mkdir(parents=True, exist_ok=True)
    (out / user_file).write_text("the user's")
    capsys.readouterr()
    assert main([*args, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "not made by dvrk-dart" in err, err
    assert _snapshot(out) == {user_file: b"the user's"}


def test_report_refuses_a_user_site(tmp_path, capsys):
    site = tmp_path / "site"
    (site / "figures").mkdir(parents=True)
    (site / "index.html").write_text("mine")
    (site / "figures" / "photo.png").write_bytes(b"\x89PNG")
    runs = tmp_path / "runs"
    runs.mkdir()
    before = _snapshot(site)
    assert main(["report", "--runs", str(runs), "--out", str(site)]) == 2
    assert _snapshot(site) == before


@pytest.mark.parametrize("where", ["the bag itself", "inside the bag"])
def test_import_never_writes_over_its_input(tmp_path, capsys, where):
    bag = tmp_path / "bag"
    bag.mkdir()
    (bag / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
    out = bag if where == "the bag itself" else bag / "metadata.yaml"
    before = _snapshot(bag)
    capsys.readouterr()
    assert main(["import", str(bag), "--out", str(out), "--force"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "input" in err, err
    assert _snapshot(bag) == before


def test_an_output_folder_that_cannot_be_made_is_named_as_given(tmp_path):
    """Under a read-only place (/proc) the error named the hidden folder built
    beside --out (/proc/.x.building-...), not the user's folder."""
    with pytest.raises(DvrkDartError) as caught:
        with building_folder(Path("/proc/dvrk-dart-test-out"), "run"):
            pytest.fail("the folder cannot be built there")
    message = str(caught.value)
    assert message.startswith("/proc/dvrk-dart-test-out: the output folder cannot be made there") and ".building" not in message


def test_a_file_the_bench_writes_in_the_validation_folder_is_the_tool_s(tmp_path):
    """make bench writes out/bench.json: make validate then refused out/ ("not what dvrk-dart wrote there")."""
    from dvrk_dart.io.outputs import check_shared_folder, mark_written
    from dvrk_dart.pipeline import VALIDATION_KIND

    (tmp_path / "bench.json").write_text("{}")
    mark_written(tmp_path, VALIDATION_KIND, "bench.json")
    assert check_shared_folder(tmp_path, VALIDATION_KIND) == tmp_path
    (tmp_path / "mine.txt").write_text("a user's")  # a file of the user's is still refused
    with pytest.raises(DvrkDartError, match="mine.txt is not what dvrk-dart wrote there"):
        check_shared_folder(tmp_path, VALIDATION_KIND)

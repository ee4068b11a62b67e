"""Batch input expansion (files, folders, globs, --recursive), output paths, --skip-existing
and leftover temporary files: plain Python, no Blender."""

from __future__ import annotations

import os

import pytest
from eegt_blender.batch import inputs


def touch(path, text="v 0 0 0\n", mtime=None):
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    if mtime is not None:
        os.utime(path, ns=(mtime, mtime))
    return path


@pytest.fixture
def tree(tmp_path):
    """in/a.obj in/b.PLY in/notes.txt in/.hidden.obj in/sub/c.stl in/sub/deep/d.blend
    in/.git/e.obj"""
    root = tmp_path / "in"
    for rel in ("a.obj", "b.PLY", "notes.txt", ".hidden.obj", "sub/c.stl", "sub/deep/d.blend",
                ".git/e.obj"):
        touch(root / rel)
    return root


def rels(sources):
    return [s.rel for s in sources]


def test_folder_top_level_only_without_recursive(tree):
    sources, notes = inputs.expand([str(tree)])
    assert rels(sources) == ["a.obj", "b.PLY"]  # mesh types in any case, no hidden, no txt
    assert notes == []
    assert all(s.problem is None for s in sources)


def test_folder_recursive_keeps_relative_paths_and_skips_hidden_folders(tree):
    sources, _ = inputs.expand([str(tree)], recursive=True)
    assert rels(sources) == ["a.obj", "b.PLY", os.path.join("sub", "c.stl"),
                             os.path.join("sub", "deep", "d.blend")]


def test_empty_folder_note_hints_at_recursive(tmp_path):
    touch(tmp_path / "only" / "sub" / "x.obj")
    sources, notes = inputs.expand([str(tmp_path / "only")])
    assert sources == []
    assert notes == [f"eegt: folder '{tmp_path / 'only'}' has no "
                     ".blend/.obj/.ply/.stl/.msh/.vtk/.vtu/.inp/.mesh/.su2 files "
                     "(--recursive searches its subfolders)"]


def test_glob_double_star_matches_any_depth_relative_to_its_base(tree):
    pattern = str(tree / "**" / "*.stl")
    sources, notes = inputs.expand([pattern])
    assert rels(sources) == [os.path.join("sub", "c.stl")]
    assert inputs.glob_base(pattern) == str(tree)
    assert notes == []


def test_glob_matching_folders_expands_them(tree):
    sources, _ = inputs.expand([str(tree / "s*")], recursive=True)
    assert rels(sources) == [os.path.join("sub", "c.stl"), os.path.join("sub", "deep", "d.blend")]


def test_glob_without_match_gives_a_note(tmp_path):
    sources, notes = inputs.expand([str(tmp_path / "*.obj")])
    assert sources == []
    assert notes == [f"eegt: '{tmp_path / '*.obj'}' matched no "
                     ".blend/.obj/.ply/.stl/.msh/.vtk/.vtu/.inp/.mesh/.su2 files"]


def test_explicit_files_are_kept_even_unsupported_or_missing(tree, tmp_path):
    sources, _ = inputs.expand([str(tree / "notes.txt"), str(tmp_path / "gone.obj"),
                                str(tree / ".hidden.obj")])
    assert rels(sources) == ["notes.txt", "gone.obj", ".hidden.obj"]
    assert sources[0].problem == ("eegt: unsupported input type '.txt' (use .blend, .obj, "
                                  ".ply, .stl, .msh, .vtk, .vtu, .inp, .mesh or .su2)")
    assert sources[1].problem == f"eegt: cannot read input '{tmp_path / 'gone.obj'}': no such file"
    assert sources[2].problem is None


def test_each_file_once_in_the_order_given(tree):
    sources, _ = inputs.expand([str(tree / "b.PLY"), str(tree), str(tree / "*.obj")])
    assert [os.path.basename(s.path) for s in sources] == ["b.PLY", "a.obj"]


def test_output_folder_inside_an_input_folder_is_not_searched(tree):
    out = tree / "fixed"
    touch(out / "a.obj")
    sources, _ = inputs.expand([str(tree)], recursive=True, exclude=[str(out)])
    assert os.path.join("fixed", "a.obj") not in rels(sources)
    assert len(sources) == 4


def test_output_folder_that_is_the_input_folder_is_searched_whole(tree):
    """-o naming the input folder itself (--in-place): its subfolders stay inputs."""
    sources, _ = inputs.expand([str(tree)], recursive=True, exclude=[str(tree)])
    assert rels(sources) == ["a.obj", "b.PLY", os.path.join("sub", "c.stl"),
                             os.path.join("sub", "deep", "d.blend")]


def test_output_path_keeps_relative_path_with_suffix_and_format(tmp_path):
    src = inputs.Source("in/sub/c.stl", os.path.join("sub", "c.stl"))
    assert inputs.output_path(src, "out", "", None) == os.path.join("out", "sub", "c.stl")
    assert inputs.output_path(src, "out", "_fixed", "blend") == \
        os.path.join("out", "sub", "c_fixed.blend")


def test_two_inputs_writing_one_output_is_refused(tmp_path):
    a = inputs.Source(str(touch(tmp_path / "x" / "m.obj")), "m.obj")
    b = inputs.Source(str(touch(tmp_path / "y" / "m.obj")), "m.obj")
    outs = [inputs.output_path(s, str(tmp_path / "out")) for s in (a, b)]
    with pytest.raises(inputs.PlanError, match="would both write"):
        inputs.check_outputs([a, b], outs)


def test_output_replacing_its_input_is_refused_unless_in_place(tmp_path):
    a = inputs.Source(str(touch(tmp_path / "m.obj")), "m.obj")
    same = inputs.output_path(a, str(tmp_path))
    with pytest.raises(inputs.PlanError) as err:
        inputs.check_outputs([a], [same])
    assert str(err.value) == (f"eegt: the output of '{a.path}' would replace it: give "
                              "--in-place to replace it, or another -o folder, a --suffix or "
                              "a --format")
    inputs.check_outputs([a], [same], in_place=True)  # asked for
    inputs.check_outputs([a], [inputs.output_path(a, str(tmp_path), "_fixed")])  # fine


def test_same_file_through_links_and_spellings(tmp_path):
    real = touch(tmp_path / "d" / "m.obj")
    (tmp_path / "link.obj").symlink_to(real)
    (tmp_path / "dirlink").symlink_to(tmp_path / "d")
    os.link(real, tmp_path / "hard.obj")
    touch(tmp_path / "d" / "other.obj")
    for other in (real, tmp_path / "link.obj", tmp_path / "dirlink" / "m.obj",
                  tmp_path / "d" / ".." / "d" / "m.obj", tmp_path / "hard.obj"):
        assert inputs.same_file(str(real), str(other)), other
        assert inputs.replaces_input(str(real), str(other)) is not None, other
        assert inputs.replaces_input(str(real), str(other), in_place=True) is None, other
    for other in (tmp_path / "d" / "other.obj", tmp_path / "d" / "new.obj"):
        assert not inputs.same_file(str(real), str(other)), other
        assert inputs.replaces_input(str(real), str(other)) is None, other
    # a symbolic link to a file not there yet: the same path once resolved
    (tmp_path / "dangling.obj").symlink_to(tmp_path / "d" / "later.obj")
    assert inputs.same_file(str(tmp_path / "d" / "later.obj"), str(tmp_path / "dangling.obj"))
    assert inputs.replaces_input(str(real), str(real)) == (
        f"eegt: -o '{real}' is the input file itself: give --in-place to replace it, or "
        "another output")


def test_up_to_date_needs_an_output_not_older_than_its_input(tmp_path):
    inp = touch(tmp_path / "m.obj", mtime=2_000_000_000_000_000_000)
    out = tmp_path / "out.obj"
    assert not inputs.up_to_date(str(inp), str(out))  # missing
    touch(out, mtime=1_999_999_999_000_000_000)
    assert not inputs.up_to_date(str(inp), str(out))  # older
    os.utime(out, ns=(2_000_000_000_000_000_000,) * 2)
    assert inputs.up_to_date(str(inp), str(out))  # same time
    os.utime(out, ns=(2_000_000_001_000_000_000,) * 2)
    assert inputs.up_to_date(str(inp), str(out))  # newer
    assert not inputs.up_to_date(str(inp), None)
    assert not inputs.up_to_date(str(inp), str(inp))  # the input itself (--in-place)


def test_stale_temporaries_are_those_of_dead_processes_only(tmp_path):
    names = [".m.obj.eegt-tmp-111.obj", ".s.blend.eegt-tmp-222.blend@",
             ".r.json.eegt-tmp-333.json", "m.obj", ".m.obj.eegt-tmp-x.obj"]
    for n in names:
        touch(tmp_path / n)
    stale = inputs.stale_temporaries([str(tmp_path)], alive=lambda pid: pid == 333)
    assert sorted(os.path.basename(p) for p in stale) == [".m.obj.eegt-tmp-111.obj",
                                                          ".s.blend.eegt-tmp-222.blend@"]


def test_pid_alive_sees_this_process_and_not_a_reaped_one():
    import subprocess
    import sys
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()
    assert inputs.pid_alive(os.getpid())
    assert not inputs.pid_alive(p.pid)


def test_pid_alive_counts_an_unreaped_zombie_as_dead():
    """A worker killed with its batch stays a zombie where nothing reaps it; its temporary
    file must still count as stale."""
    import subprocess
    import sys
    import time
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    try:
        deadline = time.time() + 30
        while time.time() < deadline:
            with open(f"/proc/{p.pid}/stat", "rb") as fh:
                if fh.read().rsplit(b")", 1)[1].split()[0] == b"Z":
                    break
            time.sleep(0.02)
        os.kill(p.pid, 0)  # the zombie still answers a signal check
        assert not inputs.pid_alive(p.pid)
    finally:
        p.wait()

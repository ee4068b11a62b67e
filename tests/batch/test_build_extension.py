"""The extension zips bundle the manifest's wheels (meshio and rich, docs/engineers.md): the
pure zip carries them and lists them in its manifest, they alone (with NumPy) import meshio
and read and write a Gmsh file, and a missing wheel without network is one clear line."""

from __future__ import annotations

import os
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "scripts"))
import build_extension  # noqa: E402

sys.path.pop(0)


@pytest.fixture(scope="module")
def pure_zip(tmp_path_factory) -> Path:
    pytest.importorskip("bpy", reason="Blender's builder ships in the bpy wheel (make venv)")
    return Path(build_extension.build_pure(str(tmp_path_factory.mktemp("dist"))))


def test_pure_zip_carries_and_lists_meshio_and_rich(pure_zip):
    names = zipfile.ZipFile(pure_zip).namelist()
    listed = build_extension.manifest()["wheels"]
    assert [os.path.basename(w).split("-")[0] for w in listed] == ["meshio", "rich"]
    assert all(w.removeprefix("./") in names for w in listed)
    inside = tomllib.loads(zipfile.ZipFile(pure_zip).read("blender_manifest.toml").decode())
    assert inside["wheels"] == listed
    assert not any(n.startswith(("tests/", "docs/", "scripts/", "build/")) for n in names)


def test_the_bundled_wheels_alone_read_and_write_a_gmsh_file(tmp_path):
    wheels = build_extension.bundled_wheels()
    only_numpy = tmp_path / "numpy_only"
    only_numpy.mkdir()
    site = Path(np.__file__).parents[1]
    for name in ("numpy", "numpy.libs"):
        if (site / name).exists():
            (only_numpy / name).symlink_to(site / name)
    script = (
        "import sys; sys.path[:0] = sys.argv[1:]\n"
        "import numpy as np\n"
        "import meshio\n"
        "m = meshio.Mesh(np.eye(3), [('triangle', np.array([[0, 1, 2]]))])\n"
        f"meshio.write({str(tmp_path / 't.msh')!r}, m, file_format='gmsh')\n"
        f"r = meshio.read({str(tmp_path / 't.msh')!r})\n"
        "assert np.array_equal(r.points, np.eye(3)), r.points\n"
        "print(meshio.__file__, sorted({k.split('.')[0] for k in sys.modules} & "
        "{'rich', 'pygments', 'markdown_it', 'mdurl'}))\n")
    proc = subprocess.run([sys.executable, "-I", "-S", "-c", script, *wheels, str(only_numpy)],
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    where, loaded = proc.stdout.strip().splitlines()[-1].split(" ", 1)
    assert where.startswith(str(Path(wheels[0]))) and loaded.strip() == "['rich']"


def test_a_missing_wheel_without_network_is_one_line(tmp_path, monkeypatch):
    monkeypatch.setenv("PIP_NO_INDEX", "1")
    monkeypatch.setenv("PIP_FIND_LINKS", "")
    with pytest.raises(SystemExit) as exc:
        build_extension.bundled_wheels(str(tmp_path / "empty"))
    message = str(exc.value)
    assert "\n" not in message and message.startswith(
        "build: the bundled wheel meshio-5.3.5-py3-none-any.whl is not in ")
    assert "could not be downloaded" in message and not os.listdir(tmp_path / "empty")

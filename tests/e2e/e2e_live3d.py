"""Live Untangle in the real Blender's 3D View (bl_gui_live3d.py): press, moves, hold,
release with real X input, then Ctrl+Z bit-identical."""
from e2e_live import make_live_blend
from e2e_tests import ART, DISPLAY, HERE, blender, check, tail, test


@test
def t_gui_live3d_drag_undo():
    check(DISPLAY, "no X display (Xvfb did not start)")
    blend = make_live_blend()
    rc, out = blender(["--window-geometry", "0", "0", "1600", "900",
                       blend, "--python", f"{HERE}/bl_gui_live3d.py", "--", ART],
                      timeout=260, env={"DISPLAY": DISPLAY}, log="gui_live3d")
    lines = [ln for ln in out.splitlines() if ln.startswith("E2E-GUI-LIVE3D")]
    check(rc == 0 and lines and lines[-1].startswith("E2E-GUI-LIVE3D-OK"),
          f"exit code {rc}: {' | '.join(lines[-4:]) or tail(out)}")
    return lines[-1].removeprefix("E2E-GUI-LIVE3D-OK").strip()

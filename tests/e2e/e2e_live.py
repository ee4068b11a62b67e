"""Live Untangle in the real Blender's UV editor (bl_gui_live.py): a drag with real X input,
Ctrl+Z, Esc mid-drag."""
import os

from e2e_tests import ART, DISPLAY, HERE, OUT, blender, check, tail, test

LIVE_BLEND = f"{OUT}/live_input.blend"


def make_live_blend():
    if not os.path.isfile(LIVE_BLEND):
        rc, out = blender(["-b", "--factory-startup", "--python-exit-code", "1", "--python",
                           f"{HERE}/bl_make_live_blend.py", "--", LIVE_BLEND],
                          timeout=120, log="make_live_blend")
        check(rc == 0 and os.path.isfile(LIVE_BLEND), f"making the live .blend: rc={rc}: "
                                                      f"{tail(out)}")
    return LIVE_BLEND


@test
def t_gui_live_drag_undo_esc():
    check(DISPLAY, "no X display (Xvfb did not start)")
    blend = make_live_blend()
    rc, out = blender(["--window-geometry", "0", "0", "1600", "900",
                       blend, "--python", f"{HERE}/bl_gui_live.py", "--", ART],
                      timeout=260, env={"DISPLAY": DISPLAY}, log="gui_live")
    lines = [ln for ln in out.splitlines() if ln.startswith("E2E-GUI-LIVE")]
    check(rc == 0 and lines and lines[-1].startswith("E2E-GUI-LIVE-OK"),
          f"exit code {rc}: {' | '.join(lines[-4:]) or tail(out)}")
    return lines[-1].removeprefix("E2E-GUI-LIVE-OK").strip()

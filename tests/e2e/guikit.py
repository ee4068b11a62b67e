"""Shared pieces of the GUI tests run inside the real Blender under Xvfb (1600x900, window at
0,0): real X input with xdotool, screenshots with ImageMagick, buttons found by hovering and
copying their Python command (Blender has no API for button positions), and the timer loop
that runs a test written as a generator (each ``yield`` gives Blender time to handle events).

A test script calls ``start(steps_generator, art_dir, tag)``; it ends Blender with
``<TAG>-OK`` / ``<TAG>-FAIL`` as its last line.
"""
import os
import subprocess
import sys
import time
import traceback

import bpy

SCREEN_H = 900
T0 = time.time()
ART = "."
TAG = "E2E-GUI"


class CheckFailed(Exception):
    pass


def check(cond, msg):
    if not cond:
        raise CheckFailed(msg)


def live_frames():
    """The frames Live Untangle's tools ran (the extension's LAST_FRAMES: (frame, times))."""
    ext = sys.modules["bl_ext.user_default.eegt_blender"]
    return ext.operators.live.ops_live.LAST_FRAMES


def live_settled(count):
    """More than ``count`` live frames ran and the last one is settled (``LiveFrame.settled``:
    untangled, no pull under way, smoothed)."""
    f = live_frames()
    return len(f) > count and f[-1][0].settled


def n_ops():
    """Operators registered in the window manager (one more per undo step pushed)."""
    return len(bpy.context.window_manager.operators)


def log(msg):
    print(f"{TAG} {time.time() - T0:6.1f}s {msg}", flush=True)


def finish(ok, msg):
    print(f"{TAG}-{'OK' if ok else 'FAIL'} {msg}", flush=True)
    sys.stdout.flush()
    os._exit(0 if ok else 1)  # a raise inside a timer would leave Blender running


def xdo(*args):
    subprocess.run(["xdotool", *map(str, args)], check=True, timeout=10)


def to_x11(wx, wy):
    """Blender window coordinates (origin bottom-left) -> X11 screen (origin top-left)."""
    return int(wx), int(SCREEN_H - wy)


def shot(name, region=None, resize=None):
    """Screenshot of the whole screen, or cropped to a region (optionally resized)."""
    cmd = ["import", "-window", "root"]
    if region is not None:
        x, y = to_x11(region.x, region.y + region.height)
        cmd += ["-crop", f"{region.width}x{region.height}+{x}+{y}"]
    if resize:
        cmd += ["-resize", resize]
    subprocess.run([*cmd, f"{ART}/{name}.png"], check=True, timeout=30)


def wait_until(cond, timeout, step=0.2):
    """Generator helper: yield until cond() is true; returns whether it became true."""
    end = time.time() + timeout
    while time.time() < end:
        if cond():
            return True
        yield step
    return cond()


def probe(points, key, match):
    """Hover each (x11) point, press `key`, and return the first point whose clipboard text
    satisfies match(text), moved down to the middle of the hit (the first hit is usually the
    button's top edge). Generator: yields between events so Blender handles them."""
    wm = bpy.context.window_manager

    def hit(x, y):
        wm.clipboard = ""
        xdo("mousemove", x, y)
        yield 0.12
        xdo("key", key)
        yield 0.12
        text = wm.clipboard
        if os.environ.get("E2E_GUI_DEBUG"):
            log(f"probe {key} at {x},{y}: {text!r}")
        return text if text and match(text) else None

    for x, y in points:
        text = yield from hit(x, y)
        if text:
            last = y
            for dy in range(3, 40, 3):  # X11 y grows downwards
                if not (yield from hit(x, y + dy)):
                    break
                last = y + dy
            return (x, (y + last) // 2), text
    return None, None


def click(pt):
    """Hover first, let Blender activate the button under the mouse, then click: a press
    arriving together with the move that enters a button can be lost."""
    xdo("mousemove", *pt)
    yield 0.3
    xdo("click", 1)


def open_tab(region, name):
    """Click down a sidebar's tab strip (its right edge) until tab `name` is active."""
    tab_x = region.x + region.width - 10
    clicks = 0
    for wy in range(region.y + region.height - 15, region.y + 20, -14):
        if region.active_panel_category == name:
            break
        xdo("mousemove", *to_x11(tab_x, wy), "click", 1)
        clicks += 1
        yield 0.25
    check(region.active_panel_category == name,
          f"no click on the tab strip opened the {name} tab (now "
          f"{region.active_panel_category!r})")
    return clicks


def start(generator, art, tag, watchdog_s=240.0):
    """Run the test generator from Blender timers; a watchdog ends a hung test."""
    global ART, TAG
    ART, TAG = art, tag

    def tick():
        try:
            return next(generator)
        except StopIteration:
            finish(False, "test ended without a verdict")
        except CheckFailed as e:
            shot("gui_failure")
            finish(False, str(e))
        except Exception:
            finish(False, traceback.format_exc().replace("\n", " | "))

    def watchdog():
        finish(False, f"watchdog: GUI test took more than {watchdog_s:.0f} s")

    bpy.app.timers.register(tick, first_interval=2.0)
    bpy.app.timers.register(watchdog, first_interval=watchdog_s)

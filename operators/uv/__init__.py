# SPDX-License-Identifier: GPL-3.0-or-later
"""UV runs: UV map read/write, the UV runner, the UV operator, its settings and panel."""

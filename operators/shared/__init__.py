# SPDX-License-Identifier: GPL-3.0-or-later
"""What mesh runs, UV runs, the command and the panels share: the run result and the
mode switching of the operators."""

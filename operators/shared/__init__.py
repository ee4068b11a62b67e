# SPDX-License-Identifier: GPL-3.0-or-later
"""What mesh runs, UV runs, the live tools, the command and the panels share: the run result
(``result``) and the wording of its stats (``report_lines``), the operators' run machinery
(``run_mixin``), whether a mesh may be written (``refusal``), progress callbacks
(``progress``) and the mode switching of the operators (``modes``)."""

# SPDX-License-Identifier: GPL-3.0-or-later
"""The ``eegt`` command-line command: argument parsing, the single-file run, output files,
the batch of many files and the JSON report."""

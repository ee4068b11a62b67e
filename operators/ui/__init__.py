# SPDX-License-Identifier: GPL-3.0-or-later
"""The sidebar: scene settings (properties), the add-on preferences and the panel."""

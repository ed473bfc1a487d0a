"""The MOWS calibrator node (issue 12)."""

"""The lab's answer: ``lab_report`` (:func:`analyse`, the whole pipeline as the CLI and the live
node run it, and its :class:`LabReport`) and ``html_report`` (the report as HTML with plots).

May import: every other lab package and the core below the lab.
"""

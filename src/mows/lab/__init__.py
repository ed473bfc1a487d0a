"""The model lab: how well the MOWS frequency model explains measurements, where it fails,
which physical effect is missing, and how much adding it helps (docs/model_lab.md).

Quick use::

    from mows.lab import load_table, analyse
    from mows.physics.probe import Probe

    report = analyse(load_table("sweep.csv"), Probe.from_yaml("probe.yaml"), auto=True)
    print(report.verdict, report.structure)

Building blocks: :func:`load_table` / :class:`MeasurementTable` (CSV and bags),
:class:`FrequencyModel` (Eq. 6 + effects, ``+`` composes, ``fit``), :func:`catalog` and the
:func:`effect` decorator for plugins, :func:`diagnose` (candidates, groups, verdict),
:func:`analyse` (all of it, for the live node) and :func:`write_report` (HTML).
"""
from mows.lab.analysis import LabReport, analyse
from mows.lab.diagnose import Diagnosis, diagnose, residual_structure
from mows.lab.effects import CATALOG, Effect, Parameter, catalog, effect, load_plugins
from mows.lab.model import FitResult, FrequencyModel
from mows.lab.table import MeasurementTable, MissingColumnError, TableError, from_bag, load_table, read_csv


def write_report(report, path):
    """Write ``report`` (a :class:`LabReport`) as a self-contained HTML page."""
    from mows.lab.report import write_html

    return write_html(report, path)


__all__ = ["CATALOG", "Diagnosis", "Effect", "FitResult", "FrequencyModel", "LabReport", "MeasurementTable",
           "MissingColumnError", "Parameter", "TableError", "analyse", "catalog", "diagnose", "effect",
           "from_bag", "load_plugins", "load_table", "read_csv", "residual_structure", "write_report"]

"""The model lab: how well the MOWS frequency model explains measurements, where it fails,
which physical effect is missing, and how much adding it helps (docs/model_lab.md).

Quick use::

    from mows.lab import ProbeSet, load_table, analyse
    from mows.physics.probe import Probe

    report = analyse(load_table("sweep.csv"), ProbeSet.one(Probe.from_yaml("probe.yaml")), auto=True)
    print(report.verdict, report.structure)

The sub-packages form a pipeline and are layered in that order: each imports only those
before it (and, outside the lab, ``mows.sweep``, ``mows.estimate``, ``mows.device``, ``mows.sim``,
``mows.physics`` and ``mows.records``), never one after it. Each one's docstring lists its modules.

1. ``data``: the measurement table, its readers (CSV, bags, sweeps), reference fields, the
   probes of a table of several and their neighbours' field, and synthetic tables from
   independent physics.
2. ``model``: the per-row configuration through the full potential, effects, plugins, the
   catalog, and the frequency model's weighted least-squares fit.
3. ``diagnosis``: residual structure, each effect as the missing one, exact aliases, effects
   the table cannot tell apart, the search beyond the catalog, and the verdict.
4. ``selection``: stepwise model selection and the error history.
5. ``report``: :func:`analyse` (all of it) with its :class:`LabReport`, and the HTML report.

Beside them, ``chirp`` (inside one recorded ring-down, ``mows lab ringdown``) imports no lab
module, and ``progress`` (what the long loops are doing, for a front end's progress bar:
:func:`mows.lab.progress.stage`) imports none either; any module may import it.

This package's ``__init__`` re-exports the public names; the CLI (``mows.cli.lab``), the bench
and the nodes import from here.
"""

from mows.lab import progress
from mows.lab.data.probe_rows import ProbeSet, with_probes
from mows.lab.data.readers import from_bag, from_sweep, is_bag, load_table, read_csv
from mows.lab.data.reference import reference_at, reference_columns, swept_reference_at, with_reference
from mows.lab.data.table import MeasurementTable, MissingColumnError, TableError
from mows.lab.diagnosis.discovery import DiscoveredTerm, Discovery, discover
from mows.lab.diagnosis.residual_structure import residual_structure
from mows.lab.diagnosis.verdict import Diagnosis, Verdict, diagnose
from mows.lab.model.catalog import CATALOG, catalog
from mows.lab.model.effects import Effect, Parameter
from mows.lab.model.frequency_model import FitResult, FrequencyModel
from mows.lab.model.plugins import effect, load_plugins
from mows.lab.report.html_report import write_html as write_report
from mows.lab.report.lab_report import LabReport, analyse, analyse_discovering, analyse_sweep

__all__ = [
    "CATALOG",
    "Diagnosis",
    "DiscoveredTerm",
    "Discovery",
    "Effect",
    "FitResult",
    "FrequencyModel",
    "LabReport",
    "MeasurementTable",
    "MissingColumnError",
    "Parameter",
    "ProbeSet",
    "TableError",
    "Verdict",
    "analyse",
    "analyse_discovering",
    "analyse_sweep",
    "catalog",
    "diagnose",
    "discover",
    "effect",
    "from_bag",
    "from_sweep",
    "is_bag",
    "load_plugins",
    "load_table",
    "progress",
    "read_csv",
    "reference_at",
    "reference_columns",
    "residual_structure",
    "swept_reference_at",
    "with_probes",
    "with_reference",
    "write_report",
]

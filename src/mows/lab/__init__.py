"""The model lab: how well the MOWS frequency model explains measurements, where it fails,
which physical effect is missing, and how much adding it helps (docs/model_lab.md).

Quick use::

    from mows.lab import load_table, analyse
    from mows.physics.probe import Probe

    report = analyse(load_table("sweep.csv"), Probe.from_yaml("probe.yaml"), auto=True)
    print(report.verdict, report.structure)

The modules form a pipeline, table → model and effects → fit → residual structure and
candidates → search → report, and are layered in that order: each module imports only modules
above it in this list (and, outside the lab, ``mows.records``, ``mows.physics``, ``mows.sim``,
``mows.device``, ``mows.estimate`` and ``mows.sweep``), never one below it.

1. ``table``: :class:`MeasurementTable`, its columns, validation and errors. Imports no lab module.
2. ``reference``: the reference field of a static source (field source, mapping, file or
   scenario) as table columns. Imports ``table``.
3. ``readers``: :func:`load_table`: CSV, the project's bags, rotation sweeps. Imports ``table``,
   ``reference``.
4. ``synth``: tables from independent physics and from the simulator and estimator (test data).
   Imports ``table``, ``reference``.
5. ``physics``: the per-row :class:`~mows.lab.physics.Configuration` and its frequency through
   the potential. Imports no lab module.
6. ``effects``: the :class:`Effect` and :class:`Parameter` types. Imports ``table``, ``physics``.
7. ``plugins``: the :func:`effect` decorator and :func:`load_plugins`. Imports ``effects``.
8. ``catalog``: the built-in effects, :func:`catalog`, ``resolve``. Imports ``physics``,
   ``effects``, ``plugins``.
9. ``fitting``: one model's weighted least-squares problem on a table and the fitted
   :class:`FitResult`. Imports ``table``.
10. ``model``: :class:`FrequencyModel` (Eq. 6 + effects, ``+`` composes) and its fit. Imports
    ``table``, ``physics``, ``effects``, ``fitting``.
11. ``physical_aliases``: exact physical aliases in words and numbers (gravity ≡ field offset …).
    Imports ``physics``.
12. ``algebra``: projections orthogonal to a fit and score tests. Imports no lab module.
13. ``structure``: :func:`residual_structure` (harmonics of θ0, covariate trends). Imports ``algebra``.
14. ``candidates``: each effect tested as the missing one, free and at physics. Imports
    ``algebra``, ``effects``.
15. ``whatif``: what-if variants of a table (more angles, half amplitude, …). Imports no lab module.
16. ``groups``: effects the table cannot tell apart (candidates, and those the model absorbs), and
    the measurement that would. Imports ``physical_aliases``, ``algebra``, ``candidates``, ``whatif``.
17. ``diagnose``: :func:`diagnose`: structure, candidates, groups, verdict. Imports ``structure``,
    ``candidates``, ``groups``.
18. ``search``: stepwise model selection, physics preferred to generic terms, the error history.
    Imports ``effects``, ``physical_aliases``, ``candidates``, ``diagnose``.
19. ``analysis``: :func:`analyse` (all of it, for the live node) and :class:`LabReport`. Imports
    ``table``, ``readers``, ``physics``, ``catalog``, ``model``, ``candidates``, ``diagnose``,
    ``search``.
20. ``report``: :func:`write_report` (HTML with plots). Imports no lab module (it reads a
    :class:`LabReport`).
21. ``chirp``: inside one recorded ring-down, the chirp and the effect that explains it
    (``mows lab ringdown``). Imports no lab module.

Below them all, ``progress`` (what the long loops are doing, for a front end's progress bar:
:func:`mows.lab.progress.stage`) imports no lab module; any module may import it.

This package's ``__init__`` re-exports the public names; the CLI (``mows.cli.lab``), the bench
and the nodes import from here.
"""

from mows.lab import progress
from mows.lab.analysis import LabReport, analyse
from mows.lab.catalog import CATALOG, catalog
from mows.lab.diagnose import Diagnosis, diagnose
from mows.lab.effects import Effect, Parameter
from mows.lab.model import FitResult, FrequencyModel
from mows.lab.plugins import effect, load_plugins
from mows.lab.readers import from_bag, from_sweep, is_bag, load_table, read_csv
from mows.lab.reference import reference_at, reference_columns
from mows.lab.report import write_html as write_report
from mows.lab.structure import residual_structure
from mows.lab.table import MeasurementTable, MissingColumnError, TableError

__all__ = [
    "CATALOG",
    "Diagnosis",
    "Effect",
    "FitResult",
    "FrequencyModel",
    "LabReport",
    "MeasurementTable",
    "MissingColumnError",
    "Parameter",
    "TableError",
    "analyse",
    "catalog",
    "diagnose",
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
    "write_report",
]

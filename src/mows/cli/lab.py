"""``mows lab``: compare | diagnose | add | report (docs/model_lab.md).

    mows lab compare  TABLE [--probe P]              χ²/dof, residual structure, verdict
    mows lab diagnose TABLE [--probe P]              + ranked candidate effects, groups
    mows lab add      TABLE [--probe P] EFFECT… | --auto [--discover]   refit with effects, error history;
                                                     --discover: save, add and refit the plugins found
                                                     beyond the catalog
    mows lab report   TABLE [--probe P] [-o page.html] [--auto] [EFFECT…]
    mows lab ringdown BAG   [--probe P] [--f00-hz F] [--cycle N]   inside each recorded ring-down:
                                                     chirp, damping, the effect that explains them

TABLE is a CSV file or a rosbag2 bag. ``--reference`` gives the reference field: for a bag a
MagneticField topic, for a bag or a CSV without reference columns (``mows fit --csv``) a static
field-source YAML or scenario. ``--json`` prints the machine-readable result.
User errors (bad tables, probe files, unknown effects, broken plugins) end with a one-line
message and exit status 2, never a traceback (:mod:`mows.cli.inputs`). ``report -o`` writes a
new file (an existing one only with ``--force``, never an input), whole or not at all.

Every row is analysed up to MAX_ROWS rows: the model is evaluated once per configuration
group and fitted on the groups' sufficient statistics, so the rows cost only the per-row
vectors of the diagnosis (docs/model_lab.md, "Long tables": 500 000 rows of 12 orientations
peaked at 860 MiB in ``diagnose`` and ``add``). A longer table is analysed on a stratified
random subsample of MAX_ROWS rows (seed 0; whole sweeps spread over the table, :meth:`MeasurementTable.subsample`),
said in a note; ``--all-rows`` uses every row. On a terminal
the stages show a progress bar on stderr (tqdm), never with ``--json``.
"""

from __future__ import annotations

import argparse
import json
import pathlib
import sys
import time

from tqdm import tqdm

from mows.cli.fit_bag import add_bag_arguments
from mows.cli.inputs import OneLineParser, input_file, magnet_position_m, positive_float
from mows.cli.lab_ringdown import run_ringdown
from mows.cli.lab_text import format_text
from mows.lab import analyse, analyse_discovering, is_bag, load_table, progress, with_reference, write_report
from mows.lab.chirp import PIECE_PERIODS
from mows.lab.data.scale import check_reference, table_probes
from mows.lab.data.table import check_design
from mows.physics.probe import Probe
from mows.records.files import check_output, read_input, writing

MAX_ROWS = 500_000
SUBSAMPLE_SEED = 0
REDRAW_S = 0.2  # the work bar's least interval between redraws
PAPER_PROBE_FILE = pathlib.Path(__file__).resolve().parents[1] / "physics" / "probes" / "paper.yaml"


class _IntermixedParser(OneLineParser):
    """A parser that takes options between positionals: ``TABLE --probe P EFFECT…`` as
    documented. argparse's plain parsing fills ``EFFECT…`` (nargs ``*``) with nothing at the
    first positional and then rejects the effects after ``--probe P`` as unrecognised;
    ``parse_known_intermixed_args`` reads all positionals together. It calls
    ``parse_known_args`` itself, hence the guard."""

    _intermixing = False

    def parse_known_args(self, args=None, namespace=None):
        if self._intermixing:
            return super().parse_known_args(args, namespace)
        self._intermixing = True
        try:
            return self.parse_known_intermixed_args(args, namespace)
        finally:
            self._intermixing = False


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="lab_command", required=True, parser_class=_IntermixedParser)
    helps = {
        "compare": "how well the model explains the table: χ²/dof, residual structure, verdict",
        "diagnose": "rank the catalog's effects as explanations of the residual",
        "add": "refit with named effects (or --auto) and print the error history",
        "report": "write a self-contained HTML report with plots",
    }
    for name, text in helps.items():
        command = sub.add_parser(name, help=text, description=text)
        command.add_argument("table", help="measurement table: CSV file or rosbag2 bag directory")
        command.add_argument(
            "--probe",
            action="append",
            default=[],
            metavar="[ID=]FILE",
            help="probe constants YAML (default: the paper's probe); for a table with a probe column, "
            "ID=FILE gives probe ID's constants and a bare FILE those of the probes not named (repeatable)",
        )
        command.add_argument(
            "--plugin",
            action="append",
            default=[],
            help="plugin file (.py) or entry-point name defining extra effects (repeatable)",
        )
        command.add_argument(
            "--reference",
            help="the reference field: for bags a sensor_msgs/MagneticField topic, for bags and CSV tables "
            "without reference columns a static field-source YAML or scenario",
        )
        command.add_argument(
            "--magnet-position",
            type=magnet_position_m,
            nargs=3,
            default=(0.0, 0.0, 0.0),
            metavar=("X", "Y", "Z"),
            help="probe position for a field-source reference, m",
        )
        command.add_argument(
            "--trust-reference",
            action="store_true",
            help="take the reference as given even where the ring-downs move a unit factor (10³, 10⁴, 10⁶) "
            "more or less than it says (otherwise refused as mT, gauss or µT given in T)",
        )
        command.add_argument(
            "--drop-invalid", action="store_true", help="drop rows with missing or invalid values instead of stopping"
        )
        command.add_argument("--json", action="store_true", help="print JSON instead of text")
        command.add_argument("--no-cv", action="store_true", help="skip the cross-validated errors (faster)")
        command.add_argument(
            "--all-rows",
            action="store_true",
            help=f"analyse every row of a table longer than {MAX_ROWS} rows (default: a subsample)",
        )
        command.add_argument(
            "--save-plugin",
            metavar="FILE",
            help="write the plugin of the strongest term found beyond the catalog to FILE (the file alone)",
        )
        if name in ("add", "report"):
            command.add_argument("effects", nargs="*", metavar="EFFECT", help="effects to add, in order")
            command.add_argument("--auto", action="store_true", help="add effects forward while the evidence is strong")
        if name == "add":
            command.add_argument(
                "--discover",
                action="store_true",
                help="with --auto: save the plugin of each term found beyond the catalog next to the table, "
                "add it and refit, while the error falls",
            )
        else:
            command.add_argument("--effects", default="", help="comma-separated effects already in the model")
        if name == "report":
            command.add_argument("-o", "--output", default="lab_report.html", help="HTML file to write (a new file)")
        command.add_argument("--force", action="store_true", help="replace an existing output file (never an input)")
    _add_ringdown_arguments(sub)


def _add_ringdown_arguments(sub) -> None:
    text = "inside each recorded ring-down: where a constant-frequency fit fails and which effect explains it"
    command = sub.add_parser("ringdown", help=text, description=text)
    command.add_argument("bag", help="a rosbag2 bag the driver recorded (raw blocks and excitation phases)")
    add_bag_arguments(command)
    command.add_argument(
        "--f00-hz", type=positive_float, help="calibrated zero-field frequency, Hz (default: the probe's)"
    )
    command.add_argument("--cycle", type=int, help="only this cycle id")
    command.add_argument("--piece-periods", type=positive_float, default=PIECE_PERIODS, help="periods per piece")
    command.add_argument("--json", action="store_true", help="print JSON instead of text")
    command.set_defaults(_run=run_ringdown)  # a bag, not a table: its own command


def run(args) -> int:
    for plugin in args.plugin:  # a plugin file is read as every input is: a FIFO or a device refused
        if pathlib.Path(plugin).exists() or pathlib.Path(plugin).is_symlink():
            read_input(plugin)
    default, named = probe_options(args.probe)
    inputs = [args.table, default, *named.values(), *args.plugin] + ([args.reference] if args.reference else [])
    probe = _probe(default)
    quiet = args.json or not sys.stderr.isatty()
    stages = tqdm(
        total=3 if args.lab_command == "report" else 2,
        desc=f"mows lab {args.lab_command}: reading",
        file=sys.stderr,
        disable=quiet,
        leave=False,
        bar_format="{desc} {bar} {n_fmt}/{total_fmt} stages, {elapsed}",
    )
    with stages, WorkBar(quiet) as work, progress.listening(work):
        table, probes = _table(args, probe, {i: _probe(path) for i, path in named.items()})
        if args.lab_command == "report":  # read: the files a reference pulled in are inputs too
            check_output(args.output, inputs, args.force)
        if args.save_plugin:
            check_output(args.save_plugin, inputs, args.force)
        if len(table) > MAX_ROWS and not args.all_rows:
            table = table.subsample(MAX_ROWS, SUBSAMPLE_SEED)
        stages.set_description(f"mows lab {args.lab_command}: analysing {len(table)} rows")
        stages.update()
        check_design(table)
        effects = args.effects if isinstance(args.effects, list) else [e for e in args.effects.split(",") if e]
        added: list = []
        if getattr(args, "discover", False):
            report, added = analyse_discovering(
                table, probes, _plugin_saver(args, inputs), effects, args.plugin, cross_validate=not args.no_cv
            )
        else:
            report = analyse(
                table,
                probes,
                effects=effects,
                auto=getattr(args, "auto", False),
                plugins=args.plugin,
                rank=args.lab_command != "compare",
                cross_validate=not args.no_cv,
            )
        stages.update()
        if report.base.dof <= 0:
            raise ValueError(
                f"{table.source}: {len(table)} row(s) for the base model's {report.base.k} parameters leave "
                f"{report.base.dof} degrees of freedom: nothing would test the model; measure more orientations"
            )
        if args.lab_command == "report":
            stages.set_description(f"mows lab report: writing {args.output}")
            with writing([args.output], inputs, args.force) as outputs:
                write_report(report, outputs.temporaries[0])
            stages.update()
    if args.lab_command == "report":  # on stderr beside JSON, which stdout must carry alone
        print(outputs.report(), file=sys.stderr if args.json else sys.stdout)
    if args.save_plugin:
        print(
            _save_strongest(report, args.save_plugin, inputs, args.force), file=sys.stderr if args.json else sys.stdout
        )
    if args.json:
        print(json.dumps(report.to_dict(), indent=2, default=float))
    elif args.lab_command != "report":
        print(format_text(report, table, args.lab_command))
        if added:
            print("\n" + _added_text(report, added))
    return 0


def plugin_directory(table: str) -> pathlib.Path:
    """Where ``add --discover`` saves plugins: beside the table (a CSV file or a bag directory)."""
    return pathlib.Path(table).resolve().parent


def _plugin_saver(args, inputs):
    """The function that saves a discovered term's plugin beside the table and returns its path:
    a file already there with the same text is reused; another is replaced only with --force."""

    def save(term) -> pathlib.Path:
        path = plugin_directory(args.table) / f"{term.effect_name}.py"
        if not (path.is_file() and path.read_text(encoding="utf-8") == term.plugin):
            _write_text(path, term.plugin, inputs, args.force)
        return path

    return save


def _write_text(path, text: str, inputs, force: bool) -> None:
    with writing([path], inputs, force) as outputs:
        outputs.temporaries[0].write_text(text, encoding="utf-8")


def _save_strongest(report, path, inputs, force: bool) -> str:
    """Write the strongest discovered term's plugin alone to ``path``; what was done, in words."""
    found = report.discovery
    if found is None or not found.terms:
        return f"no term beyond the catalog: {path} not written"
    term = found.terms[0]
    _write_text(path, term.plugin, inputs, force)
    return f"wrote {path}: the plugin of {term.name} ({term.reading}), written as {term.plugin_output}"


def _added_text(report, added) -> str:
    """What ``add --discover`` added: each term's plugin file, reading and parameter after the refit."""
    lines = ["added beyond the catalog (plugins saved beside the table):"]
    for term in added:
        parameter = term.plugin_parameter
        value, std = report.effect_parameter(f"{term.effect_name}.{parameter.name}")
        lines.append(
            f"  {term.effect_name}.py: {term.name}, {term.reading}; {parameter.name} = {value:.4g} ± {std:.2g} "
            f"{parameter.unit}" + (f" (last resort: {term.last_resort})" if term.last_resort else "")
        )
    return "\n".join(lines)


class WorkBar:
    """The lab's progress inside an analysis (:mod:`mows.lab.progress`) as a second bar under the
    stages: the task, how many of its items are done, and the model evaluations so far (they move
    within a long task). Redrawn at each new task, else at most every REDRAW_S; nothing at all
    when ``disable``."""

    def __init__(self, disable: bool):
        self.bar = tqdm(
            total=1,
            desc="fitting",
            file=sys.stderr,
            disable=disable,
            leave=False,
            position=1,
            bar_format="  {desc} {bar} {n_fmt}/{total_fmt}, {postfix}",
        )
        self.task: str | None = None
        self.evaluations = 0
        self.shown_s = 0.0

    def __enter__(self):
        return self

    def __exit__(self, *_):
        self.bar.close()

    def stage(self, task: str, done: int, total: int) -> None:
        new = task != self.task or done < self.bar.n
        if new:
            self.task = task
            self.bar.reset(total=total)
            self.bar.set_description_str(task, refresh=False)
        self.bar.n = done
        self._redraw(new)

    def evaluated(self) -> None:
        self.evaluations += 1
        self._redraw()

    def _redraw(self, now: bool = False) -> None:
        now_s = time.monotonic()
        if now or now_s - self.shown_s >= REDRAW_S:
            self.shown_s = now_s
            self.bar.set_postfix_str(f"{self.evaluations} model evaluations", refresh=False)
            self.bar.refresh()


def _table(args, default, named):
    """The table to analyse, with its reference, and the probes of its rows
    (:func:`mows.lab.data.scale.table_probes`);
    what is wrong with a file is blamed on that file."""
    with input_file(args.table):
        table = load_table(
            args.table,
            drop_invalid=args.drop_invalid,
            **({"reference": args.reference, "magnet_position_m": args.magnet_position} if is_bag(args.table) else {}),
        )
        probes = table_probes(table, default, named)
    if args.reference and not is_bag(args.table):
        with input_file(args.reference, "reference"):
            table = with_reference(table, args.reference, args.magnet_position)
    return check_reference(table, probes, args.trust_reference), probes


def probe_options(values: list[str]) -> tuple[str, dict[int, str]]:
    """(the default probe file, {probe id: file}) of the ``--probe`` options: ``ID=FILE`` names
    one probe's file (ID an integer), a bare ``FILE`` is the default (at most one)."""
    named: dict[int, str] = {}
    bare = []
    for value in values:
        key, sep, path = value.partition("=")
        if sep and key.strip().lstrip("-").isdigit():
            if int(key) in named:
                raise ValueError(f"--probe {value}: probe {int(key)} already has {named[int(key)]}")
            named[int(key)] = path
        else:
            bare.append(value)
    if len(bare) > 1:
        raise ValueError(
            f"--probe: {len(bare)} files without a probe id ({', '.join(bare)}): give at most one, "
            "and ID=FILE for the others"
        )
    return (bare[0] if bare else str(PAPER_PROBE_FILE)), named


def _probe(source):
    path = PAPER_PROBE_FILE if source == "paper" else pathlib.Path(source)
    return Probe.from_yaml(path)

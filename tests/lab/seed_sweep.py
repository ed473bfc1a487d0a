"""The outside-catalog cases over many noise seeds: what `mows lab add --auto --discover` ends with.

    PYTHONPATH=src:tests python -m lab.seed_sweep [CASE,CASE…] [SEEDS]

Per case (tests/lab/outside_catalog.py, channel_cases.py): the user's loop on seed 0
(:func:`mows.lab.analyse_discovering`); then on each seed the loop's final model without its
discovered plugin refitted, the search beyond the catalog run again, and the plugin the lab writes
added back. A seed counts when the reading names the case's channel and covariates, the plugin
ends at χ²/dof ≤ 1.5, and its parameter lies within 3σ of the truth (where the channel is the
truth's). A measurement kept out of the test suite (about 80 s of one core for the ten cases
of ten seeds, beside the suite's own loop on seed 0 and 40 seeds of each control); its figures
are in docs/model_lab.md, "Outside the catalog".
"""

from __future__ import annotations

import pathlib
import sys
import tempfile

from lab.outside_catalog import CASES
from mows.lab import FrequencyModel, ProbeSet, analyse_discovering, catalog, discover
from mows.lab.diagnosis.discovery.plugin_source import load_source
from mows.lab.model.catalog import resolve
from mows.physics.probe import PAPER_PROBE


def sweep(case: str, seeds: int, directory: pathlib.Path) -> int:
    """Print the case's loop and each seed's result; the number of seeds that count."""
    table, info = CASES[case](0)

    def save(term):
        path = directory / f"{term.effect_name}.py"
        path.write_text(term.plugin)
        return path

    report, added = analyse_discovering(table, ProbeSet.one(PAPER_PROBE), save, cross_validate=False)
    labels = [label for label in report.effects if label not in {term.effect_name for term in added}]
    model = FrequencyModel(ProbeSet.one(PAPER_PROBE))
    for effect in resolve(labels, catalog()):
        model = model + effect
    print(f"{case}: the loop adds {[t.name for t in added]} beside {labels}, χ²/dof {report.chi2_dof:.2f}")
    good = 0
    for seed in range(seeds):
        table, _ = CASES[case](seed)
        found = discover(model.fit(table), ProbeSet.one(PAPER_PROBE))
        if not found.terms:
            print(f"  seed {seed}: no term")
            continue
        term = found.terms[0]
        effect = load_source(term.plugin, term.effect_name)
        refit = (model + effect).fit(table)
        (parameter,) = refit.effect_parameters(effect.name)
        truth = info.discovered_truth
        within = truth is None or abs(parameter.value - truth) <= 3 * parameter.std
        counts = term.family == info.family and refit.chi2_dof <= 1.5 and within
        good += counts
        pull = "" if truth is None else f" ({(parameter.value - truth) / parameter.std:+.1f}σ)"
        print(
            f"  seed {seed}: {term.name} χ²/dof {refit.chi2_dof:.2f}, {parameter.text()}{pull}"
            + ("" if counts else " (does not count)")
        )
    print(f"  {case}: {good} of {seeds}")
    return good


if __name__ == "__main__":
    chosen = sys.argv[1].split(",") if len(sys.argv) > 1 and sys.argv[1] else sorted(CASES)
    count = int(sys.argv[2]) if len(sys.argv) > 2 else 10
    with tempfile.TemporaryDirectory() as scratch:
        for name in chosen:
            sweep(name, count, pathlib.Path(scratch))

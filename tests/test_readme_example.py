"""The README's library example runs as shown, and what it prints is right: the fitted frequency
agrees with the simulator's own ring-down frequency within the fit's stated uncertainty."""

import contextlib
import io
import re
from pathlib import Path

README = (Path(__file__).parents[1] / "README.md").read_text()


def test_the_readme_library_example_runs_and_fits_the_true_frequency():
    example = re.findall(r"```python\n(.*?)```", README, flags=re.S)
    assert len(example) == 1
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        exec(compile(example[0], "README.md", "exec"), {})
    fit = re.search(r"f = ([\d.]+) ± ([\d.]+) mHz", printed.getvalue())
    truth = re.search(r"true frequency ([\d.]+) Hz", printed.getvalue())
    assert fit and truth, printed.getvalue()
    f_hz, std_hz, true_hz = float(fit.group(1)), float(fit.group(2)) * 1e-3, float(truth.group(1))
    # Five σ: a failure is then a wrong fit, not the noise of one draw (p ≈ 6e-7).
    assert abs(f_hz - true_hz) < 5 * std_hz, printed.getvalue()

"""A static reference named by a YAML file: a field source or a scenario, read once by the one
YAML loader; a bad file is refused in one line naming the file, the key and the value."""

import re

import numpy as np
import pytest

from mows.lab.data.reference import reference_at


def test_a_source_file_and_a_scenario_file_give_their_field_at_the_probe(tmp_path):
    source = tmp_path / "uniform.yaml"
    source.write_text("type: uniform\nfield_t: [1e-6, -2E-6, .5e-6]\n")  # YAML 1.2 numbers
    field, gradient = reference_at(source, (0.01, 0.0, 0.0))
    np.testing.assert_array_equal(field, [1e-6, -2e-6, 0.5e-6])
    assert not gradient.any()
    scene = tmp_path / "scene.yaml"
    scene.write_text(
        "pose: {magnet_position_m: [0.0, 0.0, 0.0]}\nenvironment: {sources: [{type: uniform, field_t: [0, 3e-5, 0]}]}\n"
    )
    np.testing.assert_array_equal(reference_at(scene)[0], [0.0, 3e-5, 0.0])


BAD_REFERENCE_FILES = {
    "a source's vector": ("type: uniform\nfield_t: [1e-6, 0]\n", r"field_t = \[1e-06, 0\] must be a finite 3-vector"),
    "a source's NaN": (
        "type: uniform\nfield_t: [1e-6, .nan, 0]\n",
        r"field_t = \[1e-06, nan, 0\] must be a finite 3-vector",
    ),
    "a scenario's value": (
        "environment: {sources: [{type: uniform, field_t: [0, 1e-6, 0]}], temperature_k: hot}\n",
        "environment.temperature_k = 'hot' is not a number",
    ),
    "not YAML": ("type: [uniform\n", r"not valid YAML: line 2, column 1: .*"),
}


@pytest.mark.parametrize("case", BAD_REFERENCE_FILES)
def test_a_bad_reference_file_is_one_line_naming_the_file_key_and_value(tmp_path, case):
    text, message = BAD_REFERENCE_FILES[case]
    path = tmp_path / "ref.yaml"
    path.write_text(text)
    with pytest.raises(ValueError) as refused:
        reference_at(path)
    assert re.fullmatch(f"reference {re.escape(str(path))}: {message}", str(refused.value)), refused.value

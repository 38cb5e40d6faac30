"""The workflow schema: every bad value is one line and exit 2, found before any stage runs."""

from __future__ import annotations

import gzip
import os
import re
import typing
from pathlib import Path

import pytest
from typer.testing import CliRunner

from debist.cli import app
from debist.core.config import config_from_section, unknown_key_message
from debist.core.errors import WorkflowError
from debist.workflow.loader import load_workflow
from debist.workflow.schema import SECTIONS, check_workflow

ROOT = Path(__file__).resolve().parents[2]

# A small workflow on a slice of the Silverbox record (q = column 1, v1 = column 0, in V).
BASE = """\
[workflow]
name = "schema"
output_dir = "runs/schema"

[ingest]
format = "csv"
sample_time = 1.6384e-3
q = { column = 1, unit = "V" }
v1 = { column = 0, unit = "V" }

[datasets.estimation]
source = "rig.csv"
role = "estimation"
slice = [0, 3000]

[datasets.check]
source = "rig.csv"
slice = [3000, 4000]

[differentiate]
method = "spectral"
cutoff_hz = 290.0

[identify]
M = 4
input_map = "v"
rbf = ["c"]
backbone = ["linear_spring", "cubic_spring", "viscous", "offset", "input_gain"]
T_z = 0.0
trim = 100

[validate]
substeps = 1
init_samples = 50
report_unit = "mV"

[compare]
degree = 2

[study]
M = [4, 6]
max_samples = 1000

[study.differentiate]
method = "tvregdiff"
alpha = 1e-5
"""

# A virtual rig next to the CSV data (checked, not used by the data sets).
RIG = """
[physics]
b = 23e-3

[rig]
sample_time = 0.01

[rig.plant]
sensor_noise = 1e-6

[rig.experiments.identification]
profile = "identification"
seed = 1
"""


def edit(text: str, section: str, line: str) -> str:
    """Set ``line`` (``key = value``) in ``[section]``, adding the key or the section."""
    key = line.split("=", 1)[0].strip()
    lines, current, out, done = text.splitlines(), None, [], False
    for row in lines:
        header = re.fullmatch(r"\[(.+)\]", row.strip())
        if header:
            if current == section and not done:  # key absent: append to the section
                while out and not out[-1].strip():
                    out.pop()
                out += [line, ""]
                done = True
            current = header.group(1)
        elif current == section and row.split("=", 1)[0].strip() == key and not done:
            out.append(line)
            done = True
            continue
        out.append(row)
    if not done:
        out += ["", line] if current == section else ["", f"[{section}]", line]
    return "\n".join(out) + "\n"


def drop(text: str, section: str) -> str:
    """Remove ``[section]`` (only that table's header and keys)."""
    return re.sub(rf"(?m)^\[{re.escape(section)}\]\n(?:(?!\[).*\n)*", "", text)


def as_value(text: str, section: str, value: str) -> str:
    """Replace the table ``[section]`` by a plain top-level value ``section = value``."""
    text = drop(text, section)
    if section == "datasets":
        text = drop(drop(text, "datasets.estimation"), "datasets.check")
    return f"{section} = {value}\n" + text


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    """A folder with 4000 samples of the Silverbox estimation record as ``rig.csv``."""
    path = tmp_path_factory.mktemp("schema")
    with gzip.open(ROOT / "data/silverbox/SNLS80mV.csv.gz", "rt") as fh:
        lines = fh.read().splitlines()
    (path / "rig.csv").write_text("\n".join(lines[40650:44650]) + "\n")
    return path


@pytest.fixture
def write(folder, tmp_path):
    """Write a workflow text next to a copy of the data; return its path."""
    (tmp_path / "rig.csv").symlink_to(folder / "rig.csv")

    def _write(text: str, name: str = "wf.toml") -> Path:
        path = tmp_path / name
        path.write_text(text, encoding="utf-8")
        return path

    return _write


def invoke(*args: str):
    result = CliRunner().invoke(app, [str(a) for a in args])
    return result, " ".join(result.output.split())


def assert_rejected(result, output: str, fragment: str) -> None:
    assert result.exit_code == 2, output
    assert isinstance(result.exception, SystemExit), repr(result.exception)
    assert "Traceback" not in result.output
    assert fragment in output, output


# (section, line) edits of BASE and the one-line message each must produce.
BAD_VALUES = [
    ("identify", 'M = "ten"', "[identify] M: expected an integer, got 'ten'"),
    ("identify", 'sigma_n = "x"', "[identify] sigma_n: expected a number, got 'x'"),
    ("validate", 'substeps = "2"', "[validate] substeps: expected an integer, got '2'"),
    ("validate", "substeps = 1.5", "[validate] substeps: expected an integer, got 1.5"),
    ("validate", "substeps = 0", "[validate] substeps: expected an integer >= 1, got 0"),
    ("validate", "substeps = true", "[validate] substeps: expected an integer, got True"),
    ("identify", 'trim = "100"', "[identify] trim: expected an integer, got '100'"),
    ("identify", "trim = -1", "[identify] trim: expected an integer >= 0, got -1"),
    ("workflow", "output_dir = 5", "[workflow] output_dir: expected a string, got 5"),
    ("workflow", "name = 5", "[workflow] name: expected a string, got 5"),
    ("workflow", "description = 3", "[workflow] description: expected a string, got 3"),
    ("datasets.estimation", "source = 5", "[datasets.estimation] source: expected a string, got 5"),
    ("datasets.estimation", 'role = "test"', "[datasets.estimation] role: expected 'estimation'"),
    ("validate", 'published = "x"', "[validate] published: expected an array, got 'x'"),
    (
        "validate",
        'published = [{ model = "m", rms = { check = "x" } }]',
        "[validate.published] rms.check: expected a number, got 'x' (entry 1)",
    ),
    ("identify", 'published = "x"', "[identify] published: expected a table, got 'x'"),
    ("identify", 'published = { m_q = "x" }', "[identify.published] m_q: expected a number"),
    ("identify", "T_z = inf", '[identify] T_z: expected a time >= 0 [s] or "search", got inf'),
    ("identify", "T_z = nan", '[identify] T_z: expected a time >= 0 [s] or "search", got nan'),
    ("identify", "input_gain = [1, 2]", "[identify] input_gain: expected 1 gain(s), one per input"),
    ("identify", "M = 1", "[identify] M: expected an integer >= 2, got 1"),
    ("identify", 'm_q = "physics"', "[identify] m_q: 'physics' needs a [physics] section"),
    ("identify", "refine = { substeps = 1.5 }", "[identify.refine] substeps: expected an integer"),
    (
        "identify",
        "refine = { substeps = 0 }",
        "[identify.refine] substeps: expected an integer >= 1",
    ),
    ("identify", 'rbf = "c"', "[identify] rbf: expected an array, got 'c'"),
    ("identify", 'backbone = ["quartic"]', "[identify] backbone: unknown backbone term 'quartic'"),
    ("differentiate", "cutoff_hz = 0", "[differentiate] cutoff_hz: expected a number > 0, got 0"),
    ("differentiate", 'method = "kalman"', "[differentiate] method: expected one of 'tvregdiff'"),
    ("validate", "analytical = true", "[validate] analytical: true needs a [physics] section"),
    (
        "validate",
        'report_unit = "mm"',
        "[validate] report_unit: expected a unit of q (SI unit 'V')",
    ),
    ("validate", "init_samples = -1", "[validate] init_samples: expected an integer >= 0, got -1"),
    ("ingest", 'q = { column = 1, unit = "bananas" }', "[ingest] q.unit: expected a unit pint"),
    ("ingest", "q = { column = 1.5 }", "[ingest] q.column: expected an integer, got 1.5"),
    ("ingest", "gap_tolerance = 1", "[ingest] gap_tolerance: expected a number > 1, got 1"),
    (
        "datasets.estimation",
        "slice = [5, 1]",
        "[datasets.estimation] slice: expected [start, stop] [samples] with 0 <= start < stop",
    ),
    ("datasets.check", "gaps = 3", "[datasets.check] gaps: expected 'error' or 'split', got 3"),
    ("compare", "degree = 0", "[compare] degree: expected an integer >= 1, got 0"),
    ("compare", 'input_map = "v3"', "[compare] input_map: expected 'v2' or 'v', got 'v3'"),
    ("study", "M = [1]", "[study] M[0]: expected an integer >= 2, got 1"),
    ("study", "free_run = 1", "[study] free_run: expected true or false, got 1"),
    ("study.differentiate", "iterations = 2.0", "[study.differentiate] iterations: expected an"),
    ("study.differentiate", 'method = "savgol"', "[study.differentiate] method: the alpha study"),
    ("analyze", "n_b = 1", "[analyze] n_b: expected an integer >= 2, got 1"),
    ("analyze", "left = [2.0, 1.0]", "[analyze] left: expected [start, end] with start < end"),
    ("physics", "l = -0.09", "[physics] l: expected a number > 0, got -0.09"),
]

# A misspelled key in each section, with the suggestion it must get.
MISSPELLED = [
    ("workflow", 'nmae = "x"', "[workflow] unknown key 'nmae'; did you mean 'name'?"),
    (
        "ingest",
        "smaple_time = 1e-3",
        "[ingest] unknown key 'smaple_time'; did you mean 'sample_time'?",
    ),
    (
        "datasets.check",
        'sourse = "x"',
        "[datasets.check] unknown key 'sourse'; did you mean 'source'?",
    ),
    (
        "differentiate",
        "cutoff = 1.0",
        "[differentiate] unknown key 'cutoff'; did you mean 'cutoff_hz'?",
    ),
    ("identify", "sigma = 0.5", "[identify] unknown key 'sigma'; did you mean 'sigma_n'?"),
    ("identify", "refine = { window = 5 }", "[identify.refine] unknown key 'window'; did you mean"),
    ("validate", "substep = 2", "[validate] unknown key 'substep'; did you mean 'substeps'?"),
    ("compare", "degre = 3", "[compare] unknown key 'degre'; did you mean 'degree'?"),
    ("study", "max_sample = 100", "[study] unknown key 'max_sample'; did you mean 'max_samples'?"),
    ("study.identify", "MM = 4", "[study.identify] unknown key 'MM'; did you mean 'M'?"),
    ("analyze", "n_bb = 3", "[analyze] unknown key 'n_bb'; did you mean 'n_b'?"),
    ("physics", "Ee = 2e9", "[physics] unknown key 'Ee'; did you mean 'E'?"),
]

# The same, in the [rig] tables (BASE + RIG).
RIG_BAD = [
    ("rig", "sample_tim = 0.01", "[rig] unknown key 'sample_tim'; did you mean 'sample_time'?"),
    ("rig", "sample_time = 0", "[rig] sample_time: expected a number > 0, got 0"),
    ("rig.plant", "sensor_noize = 1e-6", "[rig.plant] unknown key 'sensor_noize'; did you mean"),
    ("rig.plant", "oversample = 2.5", "[rig.plant] oversample: expected an integer, got 2.5"),
    ("rig.prototype", 'b = "23 mm"', "[rig.prototype] b: expected a number, got '23 mm'"),
    ("rig.experiments.identification", 'seed = "1"', "[rig.experiments.identification] seed:"),
    ("rig.experiments.identification", "seeed = 1", "unknown key 'seeed'; did you mean 'seed'?"),
    ("rig.experiments.identification", 'format = "6"', "format: expected '5' or '7.3', got '6'"),
    ("rig.experiments.identification", "v_sub = 5000.0", "[rig.experiments.identification] "),
]

CASES = [pytest.param(*c, id=f"{c[0]}:{c[1]}") for c in BAD_VALUES + MISSPELLED]


@pytest.mark.parametrize(("section", "line", "message"), CASES)
def test_bad_value_is_one_line_and_exit_2_from_status(write, section, line, message):
    path = write(edit(BASE, section, line))
    result, output = invoke("status", path)
    assert_rejected(result, output, message)


@pytest.mark.parametrize(
    ("section", "line", "message"), [pytest.param(*c, id=f"{c[0]}:{c[1]}") for c in RIG_BAD]
)
def test_bad_rig_value_is_one_line_and_exit_2(write, section, line, message):
    path = write(edit(BASE + RIG, section, line))
    result, output = invoke("status", path)
    assert_rejected(result, output, message)


@pytest.mark.parametrize(
    ("section", "value", "echo"),
    [
        ("identify", "3", "3"),
        ("datasets", "3", "3"),
        ("differentiate", "[1, 2]", "[1, 2]"),
        ("compare", '"x"', "'x'"),
    ],
)
def test_section_given_as_a_plain_value(write, section, value, echo):
    result, output = invoke("status", write(as_value(BASE, section, value)))
    assert_rejected(result, output, f"[{section}] expected a table, got {echo}")


def test_unknown_section_gets_a_suggestion(write):
    result, output = invoke("status", write(BASE.replace("[compare]", "[compair]")))
    assert_rejected(result, output, "[compair] unknown section; did you mean [compare]?")


def test_differentiate_value_of_its_method_is_checked(write):
    text = BASE.replace(
        'method = "spectral"\ncutoff_hz = 290.0', 'method = "tvregdiff"\nalpha = "1e-7"'
    )
    result, output = invoke("status", write(text))
    message = "[differentiate] alpha: expected a number or 'auto', got '1e-7'"
    assert_rejected(result, output, message)
    result, output = invoke("status", write(BASE.replace("cutoff_hz = 290.0", "alpha = 1e-7")))
    assert_rejected(
        result, output, "unknown key 'alpha' (known keys of method 'spectral': cutoff_hz"
    )


def test_misspelled_compare_key_stops_run_before_any_stage(write, tmp_path):
    path = write(edit(BASE, "compare", "degre = 3"))
    result, output = invoke("run", path)
    assert_rejected(result, output, "[compare] unknown key 'degre'; did you mean 'degree'?")
    assert "Running" not in output
    assert not (tmp_path / "runs").exists()


@pytest.mark.parametrize(
    ("section", "line", "message"),
    [
        ("identify", 'M = "ten"', "[identify] M: expected an integer, got 'ten'"),
        ("study", "sigma_n = []", "[study] sigma_n: expected at least 1 value(s), got []"),
        ("datasets.estimation", "source = 5", "[datasets.estimation] source: expected a string"),
    ],
)
def test_run_refuses_a_bad_workflow_without_writing(write, tmp_path, section, line, message):
    result, output = invoke("run", write(edit(BASE, section, line)))
    assert_rejected(result, output, message)
    assert not (tmp_path / "runs").exists()


# --- the workflow file and its paths ------------------------------------------------------


def test_non_utf8_workflow_file(write, tmp_path):
    path = tmp_path / "latin1.toml"
    path.write_bytes(BASE.replace('"schema"', '"sch\xe9ma"').encode("latin-1"))
    result, output = invoke("status", path)
    assert_rejected(result, output, "is not UTF-8 text")


def test_workflow_path_that_is_a_directory(tmp_path):
    result, output = invoke("status", tmp_path)
    assert_rejected(result, output, "is a directory, not a TOML file")


def test_missing_workflow_file(tmp_path):
    result, output = invoke("status", tmp_path / "nothing.toml")
    assert_rejected(result, output, "nothing.toml' does not exist")


def test_out_pointing_at_a_file(write, tmp_path):
    (tmp_path / "taken").write_text("not a folder")
    result, output = invoke("status", write(BASE), "--out", tmp_path / "taken")
    assert_rejected(result, output, "taken' is a file, not a directory")
    result, output = invoke("run", write(BASE), "--out", tmp_path / "taken" / "sub")
    assert_rejected(result, output, "taken' is a file, not a directory")
    assert (tmp_path / "taken").read_text() == "not a folder"


def test_output_dir_key_naming_a_file(write, tmp_path):
    (tmp_path / "taken").write_text("x")
    result, output = invoke("status", write(edit(BASE, "workflow", 'output_dir = "taken"')))
    assert_rejected(result, output, "[workflow] output_dir '")
    assert "file," in output and "directory" in output


def _loop(folder: Path, name: str) -> Path:
    os.symlink(folder / f"{name}-b", folder / f"{name}-a")
    os.symlink(folder / f"{name}-a", folder / f"{name}-b")
    return folder / f"{name}-a"


def test_symlink_loops(write, tmp_path):
    result, output = invoke("status", _loop(tmp_path, "wf"))
    assert_rejected(result, output, "cannot be resolved")
    _loop(tmp_path, "log")
    text = BASE.replace('source = "rig.csv"\nrole', 'source = "log-a"\nrole')
    result, output = invoke("status", write(text))
    assert_rejected(result, output, "[datasets.estimation] source: file")
    assert "resolved" in output and "cannot" in output
    result, output = invoke("status", write(BASE), "--out", _loop(tmp_path, "out"))
    assert_rejected(result, output, "output folder (--out)")
    assert "resolved" in output and "cannot" in output


def test_source_that_is_a_directory(write, tmp_path):
    (tmp_path / "logs").mkdir()
    text = BASE.replace('source = "rig.csv"\nrole', 'source = "logs"\nrole')
    result, output = invoke("status", write(text))
    assert_rejected(result, output, "[datasets.estimation] source: ")
    assert "directory," in output and "rig-log" in output


# --- the schema itself --------------------------------------------------------------------


def test_base_and_shipped_workflows_pass(write):
    wf = load_workflow(write(BASE + RIG))
    assert [d.name for d in wf.datasets] == ["estimation", "check"]
    for path in sorted((ROOT / "workflows").glob("*.toml")):
        load_workflow(path)
    result, output = invoke("status", write(BASE))
    assert result.exit_code == 0, output
    assert "ingest" in output


def test_message_is_one_line_with_the_file(write):
    path = write(edit(BASE, "identify", 'M = "ten"'))
    with pytest.raises(WorkflowError) as err:
        load_workflow(path)
    assert err.value.key == "identify.M" and err.value.value == "ten"
    assert str(err.value).startswith(f"{path}: [identify] M: ")
    assert str(err.value).endswith("integer, got 'ten'")
    assert "\n" not in str(err.value)


def test_check_workflow_returns_the_typed_sections(folder):
    import tomllib

    checked = check_workflow(tomllib.loads(BASE + RIG))
    assert checked.identify.M == 4 and checked.identify.T_z == 0.0
    assert checked.compare.input_map == "v"  # inherited from [identify]
    assert checked.study[0].M == (4, 6) and checked.study[2].alpha == 1e-5
    assert checked.validate.report_unit == "mV"
    assert checked.datasets["check"][0].role == "validation"
    assert checked.datasets["estimation"][1].sample_slice == (0, 3000)
    assert checked.rig.experiments["identification"].seed == 1
    assert checked.physics.b == pytest.approx(23e-3)


def test_study_identify_overrides_are_labelled_by_their_table():
    raw = {"physics": {}, "identify": {"M": 4}, "study": {"identify": {"sigma_n": -1.0}}}
    with pytest.raises(WorkflowError) as err:
        check_workflow(raw)
    assert err.value.key == "study.identify.sigma_n"
    assert "> 0" in str(err.value)
    raw = {"physics": {}, "identify": {"sigma_n": -1.0}, "study": {"identify": {"M": 4}}}
    with pytest.raises(WorkflowError) as err:
        check_workflow(raw)
    assert err.value.key == "identify.sigma_n"
    assert "> 0" in str(err.value)


def test_dataset_ingest_overrides_are_labelled_by_their_table():
    ingest = {"sample_time": 0.01, "q": {"column": 1}, "v1": {"column": 0}}
    raw = {"ingest": ingest, "datasets": {"a": {"source": "x", "role": "estimation", "gaps": 1}}}
    with pytest.raises(WorkflowError) as err:
        check_workflow(raw)
    assert err.value.key == "datasets.a.gaps"
    assert "'error'" in str(err.value)
    assert "'split'" in str(err.value)
    raw["ingest"] = {**ingest, "gaps": 1}
    raw["datasets"]["a"].pop("gaps")
    with pytest.raises(WorkflowError) as err:
        check_workflow(raw)
    assert err.value.key == "ingest.gaps"
    assert "'error'" in str(err.value)
    assert "'split'" in str(err.value)


def test_unknown_key_message_suggests_only_close_keys():
    known = ["degree", "input_terms", "threshold"]
    assert unknown_key_message("[compare]", "treshold", known) == (
        "[compare] unknown key 'treshold'; did you mean 'threshold'? "
        "(known keys: degree, input_terms, threshold)"
    )
    assert unknown_key_message("[compare]", "zzz", known) == (
        "[compare] unknown key 'zzz' (known keys: degree, input_terms, threshold)"
    )


def test_config_from_section_message_format():
    from debist.differentiate.savgol import SavGolConfig
    from debist.validate.config import ValidateConfig

    def message(cls, section, where="[x]"):
        with pytest.raises(WorkflowError) as err:
            config_from_section(cls, section, where)
        return str(err.value)

    assert message(SavGolConfig, {"window": 20}) == "[x] window: expected an odd integer, got 20"
    assert message(SavGolConfig, {"window": 2}) == "[x] window: expected an integer >= 3, got 2"
    assert message(SavGolConfig, {"window": True}) == "[x] window: expected an integer, got True"
    assert message(SavGolConfig, 3) == "[x] expected a table, got 3"
    assert message(ValidateConfig, {"published": [{"model": "m"}]}) == (
        "[x.published] rms: required key is missing (entry 1)"
    )
    assert message(ValidateConfig, {"published": [{"model": "m", "rms": {}, "url": 1}]}) == (
        "[x.published] unknown key 'url' (entry 1)"
    )
    assert message(ValidateConfig, {"q_limit": float("inf")}) == (
        "[x] q_limit: expected a finite number, got inf"
    )


def test_literals_follow_the_registries():
    """Choices written as Literal types in the configs equal the constants they mirror."""
    from debist.identify.config import IdentifyConfig
    from debist.model.sindy import OPTIMIZERS, SindyConfig
    from debist.model.termtable import INPUT_MAPS
    from debist.rig.dspace import MAT_VERSIONS
    from debist.rig.experiment import ExperimentConfig
    from debist.simulate.freerun import INTERPOLATIONS
    from debist.validate.config import ValidateConfig

    def choices(cls, name):
        annotation = cls.__pydantic_fields__[name].annotation
        return typing.get_args(annotation)

    assert choices(IdentifyConfig, "input_map") == INPUT_MAPS
    assert choices(SindyConfig, "input_map") == INPUT_MAPS
    assert choices(SindyConfig, "optimizer") == OPTIMIZERS
    assert choices(ValidateConfig, "input_interpolation") == INTERPOLATIONS
    assert choices(ExperimentConfig, "format") == MAT_VERSIONS
    assert set(SECTIONS) >= {"workflow", "datasets", "compare", "rig"}


def test_direct_construction_is_checked_too():
    from pydantic import ValidationError

    from debist.identify.config import IdentifyConfig
    from debist.physics.params import PrototypeParams

    with pytest.raises(ValidationError):
        IdentifyConfig(M="ten")  # type: ignore[arg-type]
    with pytest.raises(ValueError):
        PrototypeParams(b=float("inf"))
    cfg = IdentifyConfig(max_condition=float("inf"))  # the studies lift the limit this way
    assert cfg.max_condition == float("inf")

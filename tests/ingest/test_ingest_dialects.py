"""Text rig logs in other dialects: semicolons and decimal commas (European exports)."""

from __future__ import annotations

import gzip

import numpy as np
import pytest

from debist.core.errors import RigLogError, WorkflowError
from debist.ingest.load import load_rig_log, read_raw
from debist.ingest.spec import IngestSpec
from debist.ingest.text import detect_decimal, detect_dialect

SECTION = {
    "time": {"name": "t", "unit": "s"},
    "q": {"name": "q", "unit": "mm"},
    "v1": {"name": "u", "unit": "kV"},
}
T = [0.0, 0.001, 0.002, 0.003, 0.004]
Q = [1.609, -0.5, 2.25, 1e-3, 3.125]
U = [0.5, 0.75, 1.0, 1.25, -1.5]


def european(t=T, q=Q, u=U) -> str:
    """The rows written the way a German-locale spreadsheet exports them."""
    rows = ["t;q;u"]
    for row in zip(t, q, u, strict=True):
        rows.append(";".join(f"{x:.6g}".replace(".", ",") for x in row))
    return "\n".join(rows) + "\n"


@pytest.mark.parametrize(
    "options",
    [{}, {"delimiter": ";", "decimal": ","}, {"decimal": ","}, {"delimiter": ";"}],
    ids=["auto", "explicit", "decimal-only", "delimiter-only"],
)
def test_semicolon_decimal_comma_values(tmp_path, options):
    path = tmp_path / "eu.csv"
    path.write_text(european())
    (df,) = load_rig_log(path, IngestSpec.from_dict({**SECTION, **options}))
    np.testing.assert_allclose(df["t"], T, rtol=0, atol=0)
    np.testing.assert_allclose(df["q"], np.array(Q) * 1e-3, rtol=1e-15)
    np.testing.assert_allclose(df["v1"], np.array(U) * 1e3, rtol=1e-15)
    assert df.attrs["units"] == {"t": "s", "q": "m", "v1": "V"}


def test_headerless_decimal_comma_is_not_taken_for_a_header(tmp_path):
    path = tmp_path / "eu.txt"
    path.write_text(european().split("\n", 1)[1])
    raw = read_raw(path, IngestSpec.from_dict({**SECTION, "time": {"column": 0, "unit": "s"}}))
    assert not raw.has_names
    assert raw.names == ["column 0", "column 1", "column 2"]
    np.testing.assert_array_equal(raw.channels[1].data, Q)


def test_tab_and_whitespace_with_decimal_comma(tmp_path):
    tab = tmp_path / "tab.txt"
    tab.write_text("0,0\t1,5\n0,1\t2,5\n0,2\t3,5\n")
    blanks = tmp_path / "blanks.txt"
    blanks.write_text("0,0  1,5\n0,1  2,5\n0,2  3,5\n")
    section = {"time": {"column": 0, "unit": "s"}, "q": {"column": 1, "unit": "m"}}
    section["v1"] = {"column": 1, "unit": "V"}
    for path in (tab, blanks):
        (df,) = load_rig_log(path, IngestSpec.from_dict(section))
        assert df["t"].tolist() == [0.0, 0.1, 0.2]
        assert df["q"].tolist() == [1.5, 2.5, 3.5]


def test_comma_csv_still_detected_as_before(tmp_path):
    path = tmp_path / "plain.csv"
    path.write_text("t,q,u\n0.0,1.609,0.5\n0.001,-0.5,0.75\n0.002,2.25,1.0\n")
    (df,) = load_rig_log(path, IngestSpec.from_dict(SECTION))
    assert df["q"].tolist() == pytest.approx([1.609e-3, -0.5e-3, 2.25e-3], rel=1e-15)
    assert df["v1"].tolist() == [500.0, 750.0, 1000.0]
    assert detect_dialect(["0.1,0.2", "0.3,0.4"]) == (",", ".")
    assert detect_dialect(["1,2", "3,4"]) == (",", ".")  # integers: a plain CSV
    assert detect_decimal(["0.5;1", "0.25;2"], ";") == "."


def test_explicit_point_on_a_decimal_comma_file_is_a_clear_error(tmp_path):
    path = tmp_path / "eu.csv"
    path.write_text(european())
    spec = IngestSpec.from_dict({**SECTION, "decimal": "."})
    with pytest.raises(RigLogError) as info:
        load_rig_log(path, spec)
    message = str(info.value)
    assert "eu.csv" in message
    assert "channel 't'" in message
    assert info.value.value == "0,001" and info.value.sample == 1
    assert "column 0" in message and "holds '0,001'" in message and "comma" in message
    assert "separator is '.'" in message
    assert 'set `decimal = ","`' in message


def test_explicit_comma_on_a_decimal_point_file_is_a_clear_error(tmp_path):
    path = tmp_path / "plain.txt"
    path.write_text("t;q;u\n0;1.5;2\n1;2.5;3\n2;3.5;4\n")
    with pytest.raises(RigLogError) as err:
        load_rig_log(path, IngestSpec.from_dict({**SECTION, "decimal": ","}))
    assert err.value.value == "1.5" and err.value.channel == "q"
    assert err.value.sample == 0


def test_decimal_key_is_validated():
    with pytest.raises(WorkflowError) as err:
        IngestSpec.from_dict({**SECTION, "decimal": ";"})
    assert err.value.key == "ingest.decimal"
    assert "';'" in str(err.value)
    with pytest.raises(WorkflowError) as err:
        IngestSpec.from_dict({**SECTION, "decimal": ",", "delimiter": ","})
    assert err.value.key == "ingest.decimal"
    assert "`delimiter`" in str(err.value)
    spec = IngestSpec.from_dict({**SECTION, "decimal": ","})
    assert spec.to_dict()["decimal"] == ","
    assert IngestSpec.from_dict(spec.to_dict()) == spec


@pytest.mark.parametrize("compress", [False, True])
def test_truncated_decimal_comma_file_is_detected(tmp_path, compress):
    t = np.arange(30) * 1e-3
    q = np.linspace(1.0, 2.0, 30)
    lines = ["t;q;u"] + [
        f"{a:.6f};{b:.6f};0,500000".replace(".", ",") for a, b in zip(t, q, strict=True)
    ]
    text = "\n".join(lines)[:-4]  # cut inside the last number: "0,50"
    path = tmp_path / ("cut.csv.gz" if compress else "cut.csv")
    if compress:
        path.write_bytes(gzip.compress(text.encode()))
    else:
        path.write_text(text)
    with pytest.raises(RigLogError) as err:
        load_rig_log(path, IngestSpec.from_dict(SECTION))
    assert err.value.sample == 31
    assert "'0,50'" in str(err.value)
    assert "has 2" in str(err.value)
    # the complete file reads
    path.write_text("\n".join(lines) + "\n")
    (df,) = load_rig_log(path, IngestSpec.from_dict(SECTION))
    assert len(df) == 30 and df["v1"].iloc[-1] == 500.0


def test_truncated_decimal_comma_file_missing_fields(tmp_path):
    path = tmp_path / "cut.csv"
    path.write_text(european()[: european().rindex(";")] + "\n")
    with pytest.raises(RigLogError) as err:
        load_rig_log(path, IngestSpec.from_dict(SECTION))
    assert err.value.sample == 6
    assert "has 2" in str(err.value)
    assert "have 3" in str(err.value)

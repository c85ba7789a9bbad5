"""Fuzz test of the command line: malformed tables and bad options for every command.

Whatever is wrong, a command must answer with exit code 2, exactly one line on stderr
("irreflect: error: ..."), no traceback, and write nothing: the folder it was pointed at
is the same before and after. The commands run in this process (``cli.main``), which is
fast enough to try hundreds of cases in seconds.
"""

from __future__ import annotations

import contextlib
import io
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from irreflect.cli import main
from irreflect.data import bundled_dir

TERRAZZO = str(bundled_dir() / "terrazzo.csv")
SCENE = str(bundled_dir() / "rooms" / "office.toml")
PROTOCOL = "gamma_deg,theta_deg,purpose\n-20,20,mirror\n-20,10,lobe_width\n-20,30,lobe_width\n" \
           "-40,-20,central\n-40,60,central\n-60,60,mirror\n-60,50,lobe_width\n-60,70,diffuse\n"


def _commands(data: str, root: Path) -> dict[str, list[str]]:
    """Every command that reads a table, with outputs under ``root`` and small budgets."""
    return {
        "fit": ["fit", data],
        "plot": ["plot", data, "--fit", "--out", str(root / "polar.png")],
        "compare": ["compare", data, "--out", str(root / "cmp")],
        "diagnose": ["diagnose", data, "--out", str(root / "diag")],
        "select": ["select", data, "--quiet", "--pop-size", "8", "--generations", "2",
                   "--max-points", "12", "--out", str(root / "sel")],
        "protocol": ["protocol", "--design-from", data, "--pop-size", "8", "--generations",
                     "2", "--out", str(root / "designed.csv")],
        "evaluate-protocol": ["evaluate-protocol", str(root / "protocol.csv"), data],
        "reproduce": ["reproduce", "--quick", "--no-progress", "--data-dir",
                      str(Path(data).parent), "--out", str(root / "report")],
        "next": ["next", data, "--n", "2", "--out", str(root / "next.csv")],
        "campaign": ["campaign", data, "--strategies", "adaptive", "--n-max", "9",
                     "--out", str(root / "camp")],
    }


def _readings_ok(data: Path) -> bool:
    """Whether ``irreflect next`` takes the table: a header alone or a few readings are a
    campaign's start, not an error."""
    import warnings

    from irreflect.campaign.io import read_readings
    from irreflect.errors import IrreflectError

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            read_readings(data)
    except IrreflectError:
        return False
    return True


def _snapshot(root: Path) -> dict[str, int]:
    return {str(p.relative_to(root)): (p.stat().st_size if p.is_file() else -1)
            for p in root.rglob("*")}


def _run(argv: list[str]) -> tuple[int, str]:
    err = io.StringIO()
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
        code = main(argv)
    return code, err.getvalue()


def _assert_refused(argv, root: Path) -> str:
    before = _snapshot(root)
    code, err = _run(argv)
    lines = err.strip().splitlines()
    assert code == 2, (argv, code, err)
    assert len(lines) == 1 and lines[0].startswith("irreflect: error: "), (argv, err)
    assert "Traceback" not in err
    assert _snapshot(root) == before, (argv, "wrote something")
    return lines[0]


# ----------------------------------------------------------------------------- tables
def _good_rows(n_gamma: int, n_theta: int, with_sigma: bool) -> pd.DataFrame:
    g, t = np.meshgrid(-10.0 * np.arange(1, n_gamma + 1), np.linspace(-60, 60, n_theta),
                       indexing="ij")
    g, t = g.ravel(), t.ravel()
    power = 0.2 + 0.5 * np.cos(np.radians(t)) + 0.01 * np.abs(g) / 10
    df = pd.DataFrame({"gamma_deg": g, "theta_deg": t, "power": power})
    if with_sigma:
        df["sigma"] = 0.01
    return df


CORRUPTIONS = (
    "extra_field", "missing_field", "separator", "decimal_comma", "utf16", "latin1",
    "binary", "duplicated_name", "text_in_number", "bool_text", "nan", "angle",
    "sigma", "all_zero", "huge_power", "mixed_signs", "duplicated_row", "header_only",
    "empty", "too_few_points", "missing_column", "parquet_bool", "parquet_text",
    "parquet_duplicated", "parquet_corrupt", "unknown_suffix", "spreadsheet",
)


@st.composite
def bad_tables(draw):
    """(file name, bytes) of a table that every command must refuse."""
    kind = draw(st.sampled_from(CORRUPTIONS))
    df = _good_rows(draw(st.integers(3, 4)), draw(st.integers(5, 9)),
                    draw(st.booleans()))
    row = draw(st.integers(0, len(df) - 1))
    col = draw(st.sampled_from(["gamma_deg", "theta_deg", "power"]))
    header = list(df.columns)
    lines = [",".join(header)] + [",".join(f"{v:g}" for v in r)
                                  for r in df.itertuples(index=False)]

    def text(ls):
        return ("\n".join(ls) + "\n").encode()

    if kind == "extra_field":
        lines[row + 1] += "," + draw(st.sampled_from(["1", "x", "", "0.5"]))
        return "t.csv", text(lines)
    if kind == "missing_field":
        lines[row + 1] = lines[row + 1].rsplit(",", 1)[0]
        return "t.csv", text(lines)
    if kind == "separator":
        sep = draw(st.sampled_from([";", "\t", "|"]))
        return "t.csv", text([line.replace(",", sep) for line in lines])
    if kind == "decimal_comma":
        if draw(st.booleans()):
            return "t.csv", text([line.replace(",", ";").replace(".", ",") for line in lines])
        cells = lines[row + 1].split(",")
        cells[header.index("power")] = '"0,5"'
        lines[row + 1] = ",".join(cells)
        return "t.csv", text(lines)
    if kind == "utf16":
        return "t.csv", "\n".join(lines).encode(draw(st.sampled_from(["utf-16", "utf-32",
                                                                      "utf-16-le"])))
    if kind == "latin1":
        lines[0] += ",material"
        lines[1:] = [line + ",caf\xe9" for line in lines[1:]]
        return "t.csv", "\n".join(lines).encode("latin-1")
    if kind == "binary":
        noise = draw(st.binary(min_size=64, max_size=256))
        return "t.csv", b"\x00\x01" + noise
    if kind == "duplicated_name":
        dup = draw(st.sampled_from(header))
        lines[0] += "," + dup
        lines[1:] = [line + ",1" for line in lines[1:]]
        return "t.csv", text(lines)
    if kind in ("text_in_number", "bool_text", "nan", "angle"):
        i = header.index(col)
        cells = lines[row + 1].split(",")
        if kind == "text_in_number":
            cells[i] = draw(st.sampled_from(["abc", "1..2", "--", "1e", "0x10", "?"]))
        elif kind == "bool_text":
            cells[i] = draw(st.sampled_from(["True", "false"]))
        elif kind == "nan":
            cells[i] = draw(st.sampled_from(["nan", "inf", "-inf", "", "NA"]))
        else:
            i = header.index(draw(st.sampled_from(["gamma_deg", "theta_deg"])))
            cells[i] = f"{-draw(st.floats(90, 1e6)):g}"
        lines[row + 1] = ",".join(cells)
        return "t.csv", text(lines)
    if kind == "sigma":
        df["sigma"] = 0.01
        df.loc[row, "sigma"] = draw(st.sampled_from([0.0, -0.01, 1e-30]))
    elif kind == "all_zero":
        df["power"] = 0.0
    elif kind == "huge_power":
        df["power"] = df["power"] * draw(st.sampled_from([1e200, 1e-200]))
    elif kind == "mixed_signs":
        df.loc[row, "gamma_deg"] = 30.0
    elif kind == "duplicated_row":
        df = pd.concat([df, df.iloc[[row]]], ignore_index=True)
    elif kind == "header_only":
        df = df.iloc[:0]
    elif kind == "empty":
        return "t.csv", draw(st.sampled_from([b"", b"\n\n", b"# only a comment\n"]))
    elif kind == "too_few_points":
        df = df.iloc[: draw(st.integers(1, 6))]
    elif kind == "missing_column":
        df = df.rename(columns={col: draw(st.sampled_from(["angle", "x", col.upper() + "s"]))})
    elif kind.startswith("parquet"):
        buf = io.BytesIO()
        if kind == "parquet_corrupt":
            return "t.parquet", b"PAR1" + draw(st.binary(min_size=8, max_size=64))
        if kind == "parquet_bool":
            df["power"] = df["power"] > 0.5
        elif kind == "parquet_text":  # complex numbers or words stored as text
            df["power"] = [f"{p}+1j" for p in df["power"]]
        else:
            import pyarrow as pa
            import pyarrow.parquet as pq

            table = pa.Table.from_arrays(
                [pa.array(df["gamma_deg"]), pa.array(df["theta_deg"]), pa.array(df["power"]),
                 pa.array(df["power"])], names=["gamma_deg", "theta_deg", "power", "power"])
            pq.write_table(table, buf)
            return "t.parquet", buf.getvalue()
        df.to_parquet(buf, index=False)
        return "t.parquet", buf.getvalue()
    elif kind == "unknown_suffix":
        return "t.xlsx", text(lines)
    elif kind == "spreadsheet":
        return "t.csv", b"PK\x03\x04" + draw(st.binary(min_size=16, max_size=64))
    return "t.csv", df.to_csv(index=False).encode()


@settings(max_examples=60, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow])
@given(table=bad_tables())
def test_every_command_refuses_a_malformed_table_in_one_line(table):
    name, content = table
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        (root / "data").mkdir()
        data = root / "data" / name
        data.write_bytes(content)
        (root / "protocol.csv").write_text(PROTOCOL)
        for command, argv in _commands(str(data), root).items():
            if command == "next" and _readings_ok(data):
                continue  # tests/test_campaign.py: next takes a header alone or few rows
            _assert_refused(argv, root)


# ----------------------------------------------------------------------------- options
#: (command, arguments) that must be refused; {data} is the bundled terrazzo table,
#: {root} a folder holding a file 'file.txt', a folder 'folder' and a garbage 'bad.ckpt'
BAD_OPTIONS = [
    ("fit", ["{data}", "--seed", "-1"]), ("fit", ["{data}", "--seed", "1.5"]),
    ("fit", ["{data}", "--model", "phong2"]), ("fit", ["{data}", "--model", "n-lobe:x"]),
    ("fit", ["{data}", "--nope"]), ("fit", []),
    ("plot", ["{data}", "--out", "{root}/x.txt"]), ("plot", ["{data}", "--out", "{root}/folder"]),
    ("plot", ["{data}", "--out", "{root}/file.txt/p.png"]), ("plot", ["{data}", "--out", "/proc/p.png"]),
    ("plot", ["{data}", "--fit", "--seed", "-3", "--out", "{root}/p.png"]),
    ("select", ["{data}", "--seed", "-1", "--out", "{root}/s"]),
    ("select", ["{data}", "--seeds", "0", "-2", "--out", "{root}/s"]),
    ("select", ["{data}", "--seeds", "1", "1", "--out", "{root}/s"]),
    ("select", ["{data}", "--scheduler", "notanaddress", "--out", "{root}/s"]),
    ("select", ["{data}", "--scheduler", "tcp://host:99999", "--out", "{root}/s"]),
    ("select", ["{data}", "--out", "{root}/file.txt"]),
    ("select", ["{data}", "--max-points", "5", "--out", "{root}/s"]),
    ("select", ["{data}", "--pop-size", "1", "--out", "{root}/s"]),
    ("select", ["{data}", "--generations", "0", "--out", "{root}/s"]),
    ("select", ["{data}", "--workers", "0", "--out", "{root}/s"]),
    ("select", ["{data}", "--checkpoint-every", "-1", "--out", "{root}/s"]),
    ("select", ["{data}", "--selector", "genetic", "--out", "{root}/s"]),
    ("select", ["{data}", "--checkpoint", "{root}/folder", "--out", "{root}/s"]),
    ("select", ["{data}", "--checkpoint", "{root}/bad.ckpt", "--pop-size", "8",
                "--generations", "2", "--max-points", "10", "--quiet", "--out", "{root}/s"]),
    ("select", ["{data}", "--seeds", "0", "1", "--checkpoint", "{root}/file.txt",
                "--out", "{root}/s"]),
    ("protocol", ["--gammas", "-20", "-40", "--out", "{root}/p.csv"]),
    ("protocol", ["--gammas", "-20", "-40", "95"]), ("protocol", ["--gammas", "nan", "1", "2"]),
    ("protocol", ["--gammas", "-20", "-40", "-60", "--theta-min", "60", "--theta-max", "-60"]),
    ("protocol", ["--gammas", "-20", "-40", "-60", "--out", "{root}/p.xyz"]),
    ("protocol", ["--gammas", "-20", "-40", "-60", "--out", "{root}/folder"]),
    ("protocol", ["--gammas", "-20", "-40", "-60", "--format", "xml"]),
    ("protocol", ["--gammas", "-20", "-40", "-60", "--mirror-offset", "-5"]),
    ("protocol", ["--gammas", "-20", "-40", "-60", "--n", "12"]),
    ("protocol", ["--design-from", "{data}", "--n", "0"]),
    ("protocol", ["--design-from", "{data}", "--seed", "-1"]),
    ("protocol", ["--design-from", "{data}", "--pop-size", "0"]),
    ("protocol", ["--design-from", "{data}", "--model", "nope", "--out", "{root}/p.csv"]),
    ("evaluate-protocol", ["{root}/file.txt", "{data}"]),
    ("evaluate-protocol", ["{root}/missing.csv", "{data}"]),
    ("evaluate-protocol", ["{protocol}", "{data}", "--tolerance", "-1"]),
    ("evaluate-protocol", ["{protocol}", "{data}", "--monte-carlo", "-4"]),
    ("evaluate-protocol", ["{protocol}", "{data}", "--angle-error", "inf"]),
    ("evaluate-protocol", ["{protocol}", "{data}", "--seed", "-1"]),
    ("evaluate-protocol", ["{protocol}", "{data}", "--model", "two_lobe"]),
    ("compare", ["{data}", "--models", "nope"]), ("compare", ["{data}", "--models", "phong@95"]),
    ("compare", ["{data}", "--models", ","]), ("compare", ["{data}", "--phong-at-deg", "nan"]),
    ("compare", ["{data}", "--seed", "-1"]), ("compare", ["{data}", "--out", "{root}/file.txt"]),
    ("compare", ["{data}", "--out", "{root}/foreign"]),
    ("diagnose", ["{data}", "--alpha", "0"]), ("diagnose", ["{data}", "--alpha", "nan"]),
    ("diagnose", ["{data}", "--max-effects", "-1"]), ("diagnose", ["{data}", "--seed", "-1"]),
    ("diagnose", ["{data}", "--extensions", "halo"]), ("diagnose", ["{data}", "--model", "x+y"]),
    ("diagnose", ["{data}", "--out", "{root}/file.txt"]),
    ("reproduce", ["--seed", "-1", "--out", "{root}/r"]),
    ("reproduce", ["--data-dir", "{root}/nothing", "--out", "{root}/r"]),
    ("reproduce", ["--data-dir", "{root}/folder", "--out", "{root}/r"]),
    ("reproduce", ["--out", "{root}/file.txt"]), ("reproduce", ["--out", "/proc/r"]),
    ("reproduce", ["--out", "{root}/foreign"]),
    ("room", ["{scene}", "--out", "{root}/file.txt"]),
    ("room", ["{scene}", "--seed", "-1", "--out", "{root}/r"]),
    ("room", ["{scene}", "--bounces", "-1", "--out", "{root}/r"]),
    ("room", ["{scene}", "--method", "raytrace", "--out", "{root}/r"]),
    ("room", ["{root}/nothing.toml", "--out", "{root}/r"]),
    ("datasets", ["--path", "terazzo"]), ("datasets", ["--path"]), ("datasets", ["--nope"]),
    ("room", ["{root}/file.txt", "--out", "{root}/r"]),
    ("room", ["{scene}", "--out", "{root}/foreign"]),
    ("next", ["{data}", "--n", "0"]), ("next", ["{data}", "--seed", "-1"]),
    ("next", ["{data}", "--gammas", "-20", "95"]), ("next", ["{data}", "--theta-step", "0"]),
    ("next", ["{data}", "--theta-min", "60", "--theta-max", "-60"]),
    ("next", ["{data}", "--gammas", "-20", "30"]), ("next", ["{data}", "--gamma-settings", "0"]),
    ("next", ["{data}", "--gamma-cost", "-1"]), ("next", ["{data}", "--out", "{root}/n.txt"]),
    ("next", ["{data}", "--out", "{root}/folder"]), ("next", ["{data}", "--out", "{data}"]),
    ("next", ["{data}", "--model", "nope"]), ("next", ["{data}", "--source-clearance", "nan"]),
    ("campaign", ["{data}", "--strategies", "greedy"]), ("campaign", ["{data}", "--n-max", "3"]),
    ("campaign", ["{data}", "--method", "spline"]), ("campaign", ["{data}", "--noise", "-1"]),
    ("campaign", ["{data}", "--seed", "-1"]),
    ("campaign", ["{data}", "--strategies", ","]), ("campaign", ["{data}", "--out", "{root}/file.txt"]),
    ("campaign", ["{data}", "--out", "{root}/foreign"]),
    ("campaign", ["{data}", "--angle-error", "45", "--strategies", "adaptive"]),
]


def _fixture_root(root: Path) -> None:
    (root / "file.txt").write_text("not a folder\n")
    (root / "folder").mkdir()
    (root / "foreign").mkdir()
    (root / "foreign" / "mine.txt").write_text("a user's file\n")
    (root / "bad.ckpt").write_bytes(b"\x80\x04garbage")
    (root / "protocol.csv").write_text(PROTOCOL)


def _argv(command, args, root: Path) -> list[str]:
    return [command] + [a.format(data=TERRAZZO, root=root, protocol=root / "protocol.csv",
                                 scene=SCENE) for a in args]


def test_the_option_catalogue_covers_every_command():
    from irreflect.cli import COMMANDS

    assert {c for c, _ in BAD_OPTIONS} == set(COMMANDS) - {"models"}


@settings(max_examples=40, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow])
@given(case=st.sampled_from(BAD_OPTIONS), extra=st.sampled_from(BAD_OPTIONS))
def test_bad_options_are_refused_in_one_line(case, extra):
    """One bad option, and the same with a second bad option of the same command added."""
    command, args = case
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        _fixture_root(root)
        _assert_refused(_argv(command, args, root), root)
        if extra[0] == command and extra[1] and args and extra[1][0] == args[0]:
            _assert_refused(_argv(command, args + extra[1][1:], root), root)


@pytest.mark.parametrize("command, args", BAD_OPTIONS,
                         ids=[f"{c}-{'-'.join(a)[:40]}" for c, a in BAD_OPTIONS])
def test_each_bad_option_is_refused(tmp_path, command, args):
    _fixture_root(tmp_path)
    _assert_refused(_argv(command, args, tmp_path), tmp_path)

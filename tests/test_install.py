"""The package as users install it: a built wheel (non-editable) carries the bundled
datasets and finds them through importlib.resources, from any working directory."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

SCRIPT = """
import json, sys
import irreflect
from irreflect.cli import main
from irreflect.data import BUNDLED, bundled_dir, load_bundled, resolve_scene
from irreflect.paper import PAPER_TABLES, paper_table, paper_tables_dir
from irreflect.room import load_scene

print(json.dumps({
    "module": irreflect.__file__,
    "bundled": str(bundled_dir()),
    "paper": str(paper_tables_dir()),
    "paper_rows": {f: len(paper_table(f)) for f in PAPER_TABLES},
    "points": {name: load_bundled(name).n_points for name in BUNDLED},
    "materials": len(load_scene(resolve_scene("office")).material_list()),
}))
sys.stdout.flush()
sys.exit(main(["fit", "terrazzo", "--json"]))  # by name, from a folder without it
"""


@pytest.mark.slow
def test_a_built_wheel_runs_from_another_folder(tmp_path):
    wheels = tmp_path / "wheels"
    subprocess.run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "-w", str(wheels),
                    str(ROOT)], check=True, capture_output=True)
    (wheel,) = wheels.glob("irreflect-*.whl")
    site = tmp_path / "site"
    with zipfile.ZipFile(wheel) as zf:
        zf.extractall(site)
    work = tmp_path / "elsewhere"
    work.mkdir()
    env = {k: v for k, v in os.environ.items() if not k.startswith("IRREFLECT_")}
    env["IRREFLECT_SHARED"] = str(tmp_path / "no-shared")  # the paper's folder out of reach
    env["PYTHONPATH"] = str(site)  # before the editable install of the checkout
    run = subprocess.run([sys.executable, "-c", SCRIPT], cwd=work, env=env,
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    first, rest = run.stdout.split("\n", 1)
    found = json.loads(first)
    assert Path(found["module"]).is_relative_to(site)
    assert Path(found["bundled"]) == site / "irreflect" / "datasets"
    assert found["points"] == {"terrazzo": 132, "plasterboard": 102, "foam_board": 132}
    assert Path(found["paper"]) == site / "irreflect" / "paper_tables"  # shipped, not ../shared
    assert found["paper_rows"]["table2_fit_quality_12pt.csv"] == 3
    assert found["paper_rows"]["table5_methods_r2.csv"] == 9
    assert found["materials"] >= 2  # from the scene's own folder
    assert 0.99 < json.loads(rest)["r2"] < 1.0

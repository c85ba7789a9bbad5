"""A pip user's install, checked end to end (called by .ci/run).

Builds the wheel of this checkout, installs it NOT editable (``pip install --target``,
dependencies from the project's environment: only PyPI is reachable and they are the same
packages), and from a working folder outside the checkout, with ../shared out of reach and
the real data hidden, runs what a pip user runs:

- ``irreflect datasets``: the bundled tables, scene and the paper's tables, in the install;
- ``irreflect fit terrazzo``: a bundled table by name;
- ``irreflect reproduce --quick``: on a cold kernel cache it announces the build, and the
  report has the paper's columns (Tables 2, 3, 5, 6 copied from the shipped tables);
- a second command that fits: the cache is warm, nothing is announced.

Exits non-zero with the reason on the first thing that is not as a pip user should see it.
Prints every command's timing.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def run(argv, cwd, env, timeout=1800):
    t0 = time.perf_counter()
    proc = subprocess.run(argv, cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=timeout)
    print(f"  $ {' '.join(str(a) for a in argv[1:]) if argv[0].endswith('python') else ' '.join(map(str, argv))}"
          f"  -> exit {proc.returncode} in {time.perf_counter() - t0:.1f} s", flush=True)
    if proc.returncode != 0:
        sys.exit(f"pip-install check: {argv} failed:\n{proc.stdout[-2000:]}\n{proc.stderr[-3000:]}")
    return proc


def check(condition, what):
    if not condition:
        sys.exit(f"pip-install check failed: {what}")
    print(f"  ok: {what}", flush=True)


def main() -> int:
    with tempfile.TemporaryDirectory(prefix="irreflect-pip-") as tmp:
        tmp = Path(tmp)
        site = tmp / "site"
        print(f"pip-install check: pip install --no-deps --target {site} {ROOT}", flush=True)
        run([sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--no-compile",
             "--target", str(site), str(ROOT)], cwd=tmp, env=dict(os.environ))
        work = tmp / "elsewhere"
        work.mkdir()
        env = {k: v for k, v in os.environ.items()
               if not k.startswith(("IRREFLECT_", "NUMBA_CACHE_DIR"))}
        env["PYTHONPATH"] = str(site)  # ahead of the checkout's editable install
        env["IRREFLECT_SHARED"] = str(tmp / "no-shared")  # the paper's folder out of reach
        env["IRREFLECT_REAL_DATA"] = str(tmp / "no-real-data")
        cli = [str(site / "bin" / "irreflect")]
        if not Path(cli[0]).exists():
            cli = [sys.executable, "-m", "irreflect"]

        where = run([sys.executable, "-c", "import irreflect; print(irreflect.__file__)"],
                    work, env).stdout.strip()
        check(Path(where).is_relative_to(site), f"irreflect is imported from the install ({where})")

        listing = json.loads(run(cli + ["datasets", "--json"], work, env).stdout)
        paths = {f["name"]: Path(f["path"]) for f in listing["bundled"]}
        check(all(p.is_relative_to(site) and p.exists() for p in paths.values()),
              f"'irreflect datasets' lists {len(paths)} files, all inside the install")
        check({"terrazzo", "office", "table2_fit_quality_12pt"} <= set(paths),
              "the datasets, the scene and the paper's tables are listed by name")

        fitted = json.loads(run(cli + ["fit", "terrazzo", "--json"], work, env).stdout)
        check(0.98 < fitted["r2"] < 1.0, f"'irreflect fit terrazzo' fits by name (R^2 {fitted['r2']:.4f})")

        proc = run(cli + ["reproduce", "--quick", "--out", "report", "--no-progress"], work, env)
        check("compiling the fitting kernel" in proc.stderr,
              "the first run announces the kernel's build: "
              + next((ln for ln in proc.stderr.splitlines() if "kernel" in ln), "(none)"))
        import pandas as pd

        t2 = pd.read_csv(work / "report" / "tables" / "table2_fit_quality.csv")
        paper2 = pd.read_csv(paths["table2_fit_quality_12pt"])
        check(t2["R^2 paper"].notna().all()
              and sorted(t2["R^2 paper"]) == sorted(paper2["r2"]),
              "reproduce --quick shows the paper's Table 2 column (R^2 paper = "
              f"{', '.join(map(str, t2['R^2 paper']))})")
        t5 = pd.read_csv(work / "report" / "tables" / "selection_table5.csv")
        check(t5["R^2 paper"].notna().all(), "and the paper's Table 5 column")
        md = (work / "report" / "report.md").read_text()
        check("not found" not in md.split("## ", 3)[1] and "paper_tables" in md,
              "the report says where the paper's columns come from")

        proc = run(cli + ["compare", "plasterboard", "--models", "two-lobe,phong"], work, env)
        check("compiling" not in proc.stderr, "a second run finds the kernel's cache warm")
    print("pip-install check: passed")
    return 0


if __name__ == "__main__":
    sys.exit(main())

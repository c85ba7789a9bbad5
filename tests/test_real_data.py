"""The real measured data in ../shared/datasets/real (skipped with a reason when absent)."""

from __future__ import annotations

import numpy as np
import pytest

from irreflect import fit, read_measurements

pytestmark = pytest.mark.real


@pytest.mark.parametrize("relpath", ["ptfe_nist/ptfe_sintered_1064nm.csv",
                                     "ptfe_nist/ptfe_sintered_351nm.csv",
                                     "rgl_epfl/rgl_paper_white.csv"])
def test_diffuse_references_fit_closely(real_dir, relpath):
    result = fit(read_measurements(real_dir / relpath))
    assert result.r2 >= 0.99, result.report()


def test_every_real_set_fits_without_error(real_dir):
    """Glossy paints leave structure the two-lobe model cannot follow: their R^2 is reported
    here (pytest -s shows it) and must only be a finite, proper fit, not hidden."""
    files = sorted(real_dir.rglob("*.csv"))
    assert len(files) >= 11
    assert KNOWN <= {p.stem for p in files}
    for path in files:
        meas = read_measurements(path)
        result = fit(meas)
        print(f"{path.stem:<26} n={meas.n_points:5d} R^2={result.r2:.4f} RMSE={result.rmse:.4g}")
        assert np.all(np.isfinite(result.values))
        assert result.r2 < 1.0
        if path.stem in KNOWN:
            assert result.r2 > 0.9, path.stem
        else:  # a material added since: the model may miss it, but never quietly
            assert result.r2 > 0.9 or not result.verdict().trustworthy, (
                path.stem, result.r2, result.verdict().summary())


#: The real sets this suite was written against; a table added beside them is fitted and
#: judged too, without their numbers (its R^2 is the material's, not irreflect's).
KNOWN = {"cornell_cayman", "cornell_krylon_blue", "ptfe_sintered_1064nm",
         "ptfe_sintered_351nm", "rgl_cc_ibiza_sunset", "rgl_cc_iris_purple_gem",
         "rgl_colodur_napoli_4f", "rgl_paper_white", "rgl_satin_rosaline", "rgl_cg_sunflower",
         "rgl_vch_golden_yellow"}

"""The quick reproduction lands inside wide bands of paper-notes §3 and writes what it promises."""

from __future__ import annotations

import json

import pytest

from continuum_gym.cli import main


@pytest.fixture(scope="module")
def quick_results(tmp_path_factory):
    out = tmp_path_factory.mktemp("reproduce")
    assert main(["reproduce", "--quick", "--out", str(out), "--json", str(out / "r.json")]) == 0
    return out, json.loads((out / "r.json").read_text())


def test_quick_reproduction_lands_in_wide_bands(quick_results):
    _, r = quick_results
    voi = r["hold"]["voi"]
    assert len(voi) == 1501 and voi[0] == pytest.approx(0.2502, abs=1e-4)
    assert voi[-1] < voi[0] - 0.05  # hold VOI decreases
    assert 0.14 <= voi[800] <= 0.18
    assert r["hold"]["max_tip_drift_m"] <= 0.3e-3
    assert 0.05 <= r["hold_sweep"]["final_voi_median"] <= 0.25
    assert r["circle"]["projected_gradient"]["mean_voi"] <= 0.7 * r["circle"]["minimum_norm"]["mean_voi"]
    assert 0.27 <= r["circle"]["minimum_norm"]["mean_voi"] <= 0.33
    assert -19 <= r["circle"]["gamma_min_deg"] <= -16 and 16 <= r["circle"]["gamma_max_deg"] <= 19
    for case in ("case1", "case2"):
        assert r[case]["dimension_reduced"]["or"] > r[case]["resolved_rate"]["or"]
    assert r["coverage"]["grid"] == 11
    assert r["coverage"]["dimension_reduced_percent"] > r["coverage"]["resolved_rate_percent"]
    assert set(r["seconds"]) == {"hold", "circle", "case_studies", "coverage"}


def test_quick_reproduction_writes_figures_and_table(quick_results):
    out, _ = quick_results
    for name in ("hold.png", "circle.png", "case1.png", "case2.png", "coverage.png", "reproduction.md"):
        assert (out / name).stat().st_size > 1000
    assert "| coverage 11x11: OR > 0.8, DR | 61.07 % |" in (out / "reproduction.md").read_text()


def test_bad_cli_input_exits_non_zero(capsys):
    assert main(["reproduce", "--grid", "1", "--out", "/tmp/never"]) == 2
    assert "--grid must be an integer >= 2" in capsys.readouterr().err
    with pytest.raises(SystemExit) as error:
        main(["no-such-command"])
    assert error.value.code == 2

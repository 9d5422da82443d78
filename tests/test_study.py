"""[study] tables: one-at-a-time variants around a scenario, overlay figures and study.json."""

import json

import pytest
import tomli_w

from robotadapt.analysis.metrics import metrics
from robotadapt.cli import main
from robotadapt.studies.scenarios import load
from robotadapt.studies.study import run_study
from robotadapt.validation import ConfigError

BASE = {
    "description": "study test",
    "robot": {"kind": "one_link"},
    "plant": {"phi": [1.0, 1.0]},
    "trajectory": {"kind": "sinusoid"},
    "controller": {"kind": "slotine_li", "Lam": 5.0, "Kv": 10.0, "Gamma": 10.0},
    "simulation": {"t_final": 3.0},
}


def _write(tmp_path, data):
    path = tmp_path / "s.toml"
    path.write_text(tomli_w.dumps(data))
    return path


def test_variants_change_only_their_key(tmp_path):
    path = _write(tmp_path, BASE | {"study": {"controller.Gamma": [1.0, 100.0]}})
    runs = run_study(load(path))["controller.Gamma"]
    assert [r.value for r in runs] == [1.0, 100.0]
    assert metrics(runs[0].result)["final_phi_error"] != metrics(runs[1].result)["final_phi_error"]
    base = load(path).run()
    same = run_study(load(_write(tmp_path, BASE | {"study": {"controller.Gamma": [10.0]}})))["controller.Gamma"][0]
    assert (same.result.x == base.x).all()


def test_cli_writes_overlays_and_summary(tmp_path):
    path = _write(tmp_path, BASE | {"study": {"controller.Gamma": [1.0, 10.0], "controller.Kv": [5.0, 20.0]}})
    assert main(["run", str(path), "--out", str(tmp_path / "out")]) == 0
    summary = json.loads((tmp_path / "out" / "study.json").read_text())
    assert [row["value"] for row in summary["controller.Kv"]] == [5.0, 20.0]
    assert (tmp_path / "out" / "study_controller_Gamma.png").stat().st_size > 1000
    assert (tmp_path / "out" / "study_controller_Kv.png").exists()


@pytest.mark.parametrize("study", [{"controller.Kv": [5.0, -1.0]}, {"controller.Kv": []}, {"controller.nope": [1]}])
def test_bad_study_names_the_key(tmp_path, study):
    with pytest.raises(ConfigError, match="study.controller"):
        load(_write(tmp_path, BASE | {"study": study}))


def test_a_study_over_whole_tables_varies_them(tmp_path):
    """Values that are tables (a trajectory, a servo) become inline tables in the variant's --set."""
    study = {"trajectory": [{"kind": "sinusoid", "amplitude": 0.5}, {"kind": "exponential_step", "final": 1.0}]}
    runs = run_study(load(_write(tmp_path, BASE | {"study": study})))["trajectory"]
    assert [r.result.ok for r in runs] == [True, True]
    assert abs(runs[0].result.q_des).max() == pytest.approx(0.5, rel=1e-3)
    assert runs[1].result.q_des[-1, 0] == pytest.approx(1.0, abs=0.1)

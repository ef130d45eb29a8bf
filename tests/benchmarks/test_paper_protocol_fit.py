"""paper_protocol_fit: the line through the 1- and 16-env paper rows, and its check against
measured rows."""

import json
import os
import sys

import pytest

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "benchmarks"))
import paper_protocol_fit as ppf  # noqa: E402


def _result(path, rows):
    path.write_text(json.dumps({"device": "GPU", "rows": [
        {"seeds": s, "envs_per_seed": e, "protocol": p, "flr_dhrl_ms_per_iter": ms}
        for s, e, p, ms in rows]}))
    return str(path)


def test_line_through_one_and_sixteen_envs_predicts_and_checks(tmp_path, capsys):
    first = _result(tmp_path / "a.json", [
        (2, 1, "paper", 99.0), (2, 16, "paper", 40.0),  # 2 ms per extra update
        (2, 256, "paper", 500.0),
        (3, 1, "paper", 5.0),  # no 16-env row: no line
        (4, 16, "fast", 1.0)])  # another protocol: ignored
    later = _result(tmp_path / "b.json", [(2, 1, "paper", 10.0)])  # the last file wins
    out = tmp_path / "fit.json"
    ppf.main([first, later, "--envs", "16,256", "--out", str(out)])
    rows = json.loads(out.read_text())["rows"]
    assert [(r["seeds"], r["envs_per_seed"]) for r in rows] == [(2, 16), (2, 256)]
    sixteen, big = rows
    assert sixteen["predicted_ms_per_iter"] == pytest.approx(40.0)
    assert sixteen["relative_error"] == pytest.approx(0.0)
    assert big["ms_per_update"] == pytest.approx(2.0)
    assert big["predicted_ms_per_iter"] == pytest.approx(10.0 + 2.0 * 255)
    assert big["relative_error"] == pytest.approx(520.0 / 500.0 - 1)
    assert big["predicted_env_steps_per_s"] == pytest.approx(1e3 * 2 * 256 / 520.0)
    assert "520.0" in capsys.readouterr().out

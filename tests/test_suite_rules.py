"""Rules of the test suite itself: shared data on CI, the slow marker."""

from __future__ import annotations

from pathlib import Path

import conftest
import pytest
import tomllib


def test_missing_shared_data_fail_on_ci_and_skip_elsewhere(monkeypatch, tmp_path):
    absent = tmp_path / "absent"
    monkeypatch.setattr(conftest, "IN_CI", True)
    with pytest.raises(pytest.fail.Exception, match="CI=true"):
        conftest.require_shared_data(absent, "the data")
    monkeypatch.setattr(conftest, "IN_CI", False)
    with pytest.raises(pytest.skip.Exception, match="the data not found"):
        conftest.require_shared_data(absent, "the data")
    assert conftest.require_shared_data(tmp_path, "the folder") == tmp_path


def test_slow_marker_is_declared_and_strict():
    config = tomllib.loads((Path(__file__).parents[1] / "pyproject.toml").read_text())
    pytest_config = config["tool"]["pytest"]["ini_options"]
    assert any(m.startswith("slow:") for m in pytest_config["markers"])
    assert "--strict-markers" in pytest_config["addopts"]

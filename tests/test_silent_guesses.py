"""Issue 25: no silent wrong number.

Each test feeds the CLI an input whose number used to be wrong without a word (a row ignored,
a default guessed, a value rounded through float64, ...) and checks the fix at its root:
either one clear refusal (exit 3, the file, the line and what was expected) or a counted
warning with the count in the JSON.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from slamrel.cli import main
from tests.test_readers_fuzz import BUNDLE


def _write(root: Path, files: dict[str, str]) -> Path:
    root.mkdir(parents=True, exist_ok=True)
    for name, text in files.items():
        (root / name).write_text(text)
    return root


def _refused(argv: list[str], capsys: pytest.CaptureFixture[str], *needles: str) -> str:
    assert main(argv) == 3
    err = capsys.readouterr().err
    assert "Traceback" not in err
    for needle in needles:
        assert needle in err, err
    return err


# ---------------------------------------------------------------- 4. misspelt manifest keys


def test_misspelt_manifest_key_is_refused_with_a_suggestion(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    meta = json.loads(BUNDLE["bundle.json"])
    meta["initial_pos"] = meta.pop("initial_pose")
    files = dict(BUNDLE, **{"bundle.json": json.dumps(meta, indent=2)})
    b = _write(tmp_path / "b", files)
    err = _refused(
        ["recover", str(b), "-o", str(tmp_path / "o.tum")],
        capsys,
        "bundle.json:",
        "'initial_pos'",
        "did you mean 'initial_pose'",
    )
    assert not (tmp_path / "o.tum").exists(), err


def test_misspelt_model_key_is_refused_and_writer_keys_are_allowed(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    meta = json.loads(BUNDLE["bundle.json"])
    meta["sensor_model"]["max_rnage"] = 5.0
    b = _write(tmp_path / "b", dict(BUNDLE, **{"bundle.json": json.dumps(meta, indent=2)}))
    _refused(
        ["recover", str(b), "-o", str(tmp_path / "o.tum")],
        capsys,
        "in sensor_model",
        "did you mean 'max_range'",
    )
    meta["sensor_model"].pop("max_rnage")
    meta["x_writer"] = {"version": 3}
    b = _write(tmp_path / "c", dict(BUNDLE, **{"bundle.json": json.dumps(meta, indent=2)}))
    assert main(["recover", str(b), "-o", str(tmp_path / "o.tum"), "-q"]) == 0

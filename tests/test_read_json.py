"""Tests for abs.errors.read_json: the one reader of a user's JSON file."""

from __future__ import annotations

import pytest

from abs.errors import CaptureError, InputError, read_json


def test_reads_an_object(tmp_path):
    (tmp_path / "a.json").write_text('{"x": [1, 2]}', encoding="utf-8")
    assert read_json(tmp_path / "a.json") == {"x": [1, 2]}


@pytest.mark.parametrize("text, words", [
    (None, "camera file not found"),
    ('{"x": [1,', "not valid JSON: Expecting value at line 1, column 10"),
    ("[1, 2]", "expected a JSON object at the top of the camera file, got array"),
    ("true", "expected a JSON object at the top of the camera file, got true/false"),
])
def test_errors_name_the_file_and_field(tmp_path, text, words):
    path = tmp_path / "c.json"
    if text is not None:
        path.write_text(text, encoding="utf-8")
    with pytest.raises(InputError) as info:
        read_json(path, what="camera file", field="--cameras")
    assert info.value.source == str(path) and info.value.field == "--cameras"
    assert words in info.value.message and str(info.value).startswith(f"{path}: --cameras: ")


def test_folder_bytes_expect_hint_and_error_type(tmp_path):
    with pytest.raises(InputError, match="expected a build file, got a folder"):
        read_json(tmp_path, what="build file")
    (tmp_path / "b.json").write_bytes(b'{"a": "\xff"}')
    with pytest.raises(InputError, match="cannot read the file"):
        read_json(tmp_path / "b.json")
    (tmp_path / "l.json").write_text("[1]", encoding="utf-8")
    assert read_json(tmp_path / "l.json", expect=(dict, list)) == [1]
    assert read_json(tmp_path / "l.json", expect=None) == [1]
    with pytest.raises(CaptureError, match=r"got array \(delete it\)"):
        read_json(tmp_path / "l.json", hint="delete it", error=CaptureError)

"""tactile_driver.taxels.resolve_layout_file: paths as given, bare names from the package config."""

from pathlib import Path

import pytest

from tactile_driver.taxels import DEFAULT_LAYOUT_FILES, load_layout, resolve_layout_file

SOURCE_CONFIG = Path(__file__).resolve().parents[2] / "src/tactile_driver/config"


@pytest.mark.parametrize("mode", sorted(DEFAULT_LAYOUT_FILES))
def test_empty_name_is_the_modes_default_with_the_source_trees_content(mode):
    path = resolve_layout_file("", mode)
    assert path.name == DEFAULT_LAYOUT_FILES[mode]
    assert path.read_text() == (SOURCE_CONFIG / DEFAULT_LAYOUT_FILES[mode]).read_text()
    assert load_layout(path).n_taxels > 0


def test_a_path_that_exists_is_taken_as_given(tmp_path, monkeypatch):
    own = tmp_path / "taxels_ring.yaml"  # same name as a packaged file: the user's file wins
    own.write_text((SOURCE_CONFIG / "taxels_ring.yaml").read_text())
    assert resolve_layout_file(str(own)) == own
    monkeypatch.chdir(tmp_path)
    assert resolve_layout_file("taxels_ring.yaml") == Path("taxels_ring.yaml")


def test_unknown_names_and_modes_fail_in_one_line():
    with pytest.raises(ValueError, match="no config/nope.yaml"):
        resolve_layout_file("nope.yaml")
    with pytest.raises(ValueError, match=r"mode one of \['2d', '3d'\]"):
        resolve_layout_file("", "4d")

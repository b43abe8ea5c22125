"""docs/parameters.md is what `fcu.edge.params_doc` generates from the parameter table now: the
page cannot go stale (regenerate it with `python -m fcu.edge.params_doc`)."""

from __future__ import annotations

from fcu.edge import params_doc
from fcu.params import SPECS


def test_the_page_is_the_generated_one():
    assert params_doc.PAGE.read_text() == params_doc.render(), (
        "docs/parameters.md is stale: run python -m fcu.edge.params_doc")


def test_the_page_lists_every_parameter_once():
    text = params_doc.render()
    for spec in SPECS:
        assert text.count(f"| `{spec.name}` |") == 1


def test_check_exits_1_on_a_stale_page(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(params_doc, "PAGE", tmp_path / "parameters.md")
    assert params_doc.main(["--check"]) == 1
    assert params_doc.main([]) == 0
    assert params_doc.main(["--check"]) == 0
    assert "stale" in capsys.readouterr().out

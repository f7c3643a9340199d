"""The one result table (adaptive_mj.study.result.Table): the same rows written as aligned text, Markdown, HTML,
CSV and JSON lines, numbers kept as numbers where the format can hold them; and the studies' tables built on it."""
import csv
import json
import math

import pytest

from adaptive_mj.study.result import Table

ROWS = [{"law": "adaptive", "margin": 0.25, "first_fail": None, "rate": {"0.5": 1.0}},
        {"law": "sigma|leak", "margin": math.inf, "first_fail": 3, "rate": [0.5, math.nan]}]


def test_csv_keeps_numbers_and_writes_none_empty_and_containers_as_json(tmp_path):
    path = Table.of(ROWS).to_csv(tmp_path / "t.csv")
    with path.open(newline="", encoding="utf-8") as f:
        got = list(csv.reader(f))
    assert got[0] == ["law", "margin", "first_fail", "rate"]
    assert got[1] == ["adaptive", "0.25", "", '{"0.5": 1.0}']
    assert got[2] == ["sigma|leak", "inf", "3", "[0.5, null]"]
    assert float(got[1][1]) == 0.25  # repr of the float: it reads back exactly


def test_jsonl_is_one_object_per_row_in_column_order_with_non_finite_as_null(tmp_path):
    path = Table.of(ROWS, ["margin", "law"]).to_jsonl(tmp_path / "t.jsonl")
    lines = path.read_text(encoding="utf-8").splitlines()
    assert [list(json.loads(x)) for x in lines] == [["margin", "law"], ["margin", "law"]]
    assert [json.loads(x) for x in lines] == [{"margin": 0.25, "law": "adaptive"},
                                              {"margin": None, "law": "sigma|leak"}]


def test_markdown_escapes_pipes_and_shows_numbers_to_4_digits():
    md = Table.of([{"a": 1.23456789, "b": "x|y", "c": None}]).to_markdown().splitlines()
    assert md == ["| a | b | c |", "|---|---|---|", "| 1.235 | x\\|y | n/a |"]


def test_text_aligns_left_and_right_columns_and_draws_a_rule():
    text = Table.of([{"name": "a", "v": 1.5}, {"name": "long", "v": 10.25}]).to_text(left=("name",), rule=True)
    assert text.splitlines() == ["name      v", "-----------", "a       1.5", "long  10.25"]


def test_write_picks_the_format_by_suffix_and_refuses_another(tmp_path):
    t = Table.of(ROWS[:1], ["law", "margin"])
    assert t.write(tmp_path / "a.md").read_text(encoding="utf-8") == t.to_markdown() + "\n"
    assert '<table class="sortable">' in t.write(tmp_path / "a.html").read_text(encoding="utf-8")
    assert t.write(tmp_path / "a.csv").read_text(encoding="utf-8").splitlines() == ["law,margin", "adaptive,0.25"]
    assert json.loads(t.write(tmp_path / "a.jsonl").read_text(encoding="utf-8")) == {"law": "adaptive",
                                                                                      "margin": 0.25}
    with pytest.raises(ValueError, match=r"a\.xlsx: a table is written as \.csv, \.jsonl, \.md or \.html, "
                                         r"not '\.xlsx'"):
        t.write(tmp_path / "a.xlsx")


def test_the_score_card_s_terminal_table_shows_both_ranks_and_the_oracle_mark():
    from adaptive_mj.study.score_card import terminal_table

    est = {"mean": 0.5, "lo": 0.4, "hi": 0.6, "n": 3, "values": [0.4, 0.5, 0.6]}
    plant = {"laws": {"mine": {"tested": True, "rank": {"performance": 2, "robustness": 1},
                               "figures": {"performance": est, "robustness": est}},
                      "truth": {"oracle": True, "rank": {"performance": 1, "robustness": 3},
                                "figures": {"performance": {**est, "mean": 0.9}, "robustness": est}}}}
    t = terminal_table(plant)
    assert t["law"] == ["  truth †", "* mine"] and t["rank S"] == [1, 2] and t["rank R"] == [3, 1]
    assert t.columns == ("rank S", "rank R", "law", "S", "R")

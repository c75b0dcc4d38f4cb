"""bench_delivery --from-csv: the rows of several processes (each its own --csv) make one table and
one plot, in paper 002's order, without running anything (issue 13: the table is run in pieces)."""
from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "bench"))
import bench_delivery  # noqa: E402


def _row(m: str, n: int, method: str, **kw) -> bench_delivery.Row:
    row = bench_delivery.Row(m, n, method, 3 * n, 3 * n, 1000.25 + n, 400.25, 0.4321, 1.5, "leg", 0, 0, "done",
                             12.5, 0, 0.0125, 0, 2.75 if method == "armo" else 0.0)
    return replace(row, **kw)


def test_rows_from_several_csvs_make_one_table_in_the_papers_order(tmp_path, monkeypatch, capsys):
    def no_run(*args, **kwargs):
        raise AssertionError("--from-csv must not simulate")

    monkeypatch.setattr(bench_delivery, "simulate", no_run)
    large = [_row("large", 100, "md"), _row("large", 20, "behavior"), _row("large", 20, "armo")]
    small = [_row("warehouse", 20, "prior"), _row("warehouse", 20, "armo", stop="wall", completed=7)]
    for name, rows in (("a.csv", large), ("b.csv", small)):
        bench_delivery.write_csv(rows, tmp_path / name)
    merged, png = tmp_path / "all.csv", tmp_path / "all.png"
    code = bench_delivery.main(["--paper002", "--from-csv", str(tmp_path / "a.csv"), str(tmp_path / "b.csv"),
                                "--csv", str(merged), "--plot", str(png), "--maps-dir", str(tmp_path / "none")])
    assert code == 0 and png.stat().st_size > 0
    back = bench_delivery.read_csv(merged)
    assert back == [small[1], small[0], large[2], large[1], large[0]]   # warehouse, large; N; ARMO, PRIOR, BBMRCA, md
    out = capsys.readouterr().out
    paper = out[out.index("\nwarehouse\n"):]
    assert paper.index("ARMO") < paper.index("PRIOR") < paper.index("\nlarge\n") < paper.index("BBMRCA")
    assert "1020!" in paper    # the unfinished ARMO row keeps its mark


def test_a_csv_row_with_a_collision_fails_the_merged_table(tmp_path, capsys):
    bench_delivery.write_csv([_row("large", 20, "md")], tmp_path / "ok.csv")
    assert bench_delivery.main(["--from-csv", str(tmp_path / "ok.csv")]) == 0      # (control)
    bench_delivery.write_csv([_row("large", 20, "md", collisions=2)], tmp_path / "bad.csv")
    assert bench_delivery.main(["--from-csv", str(tmp_path / "ok.csv"), str(tmp_path / "bad.csv")]) == 1
    assert "large N=20 md" in capsys.readouterr().err


def test_without_from_csv_the_maps_are_still_checked(tmp_path):
    with pytest.raises(SystemExit):
        bench_delivery._args(["--paper002", "--maps-dir", str(tmp_path / "none")])

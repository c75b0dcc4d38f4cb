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


# --seeds (session 29): one row's CTime moves +-10% from seed to seed, so a table compares planners over
# several seeds: every row per seed, then a summary per map, N and method and md against PRIOR seed by seed.

@pytest.mark.parametrize("text, seeds", [("0-4", [0, 1, 2, 3, 4]), ("0,2,5", [0, 2, 5]), ("7", [7]),
                                         (" 3-4 , 1 ", [3, 4, 1]), ("0-2,1-3", [0, 1, 2, 3])])
def test_seeds_are_ranges_and_lists(text, seeds):
    assert bench_delivery.parse_seeds(text) == seeds
    assert bench_delivery._args(["--seeds", text, "--maps", "warehouse"]).seeds == seeds


def test_without_seeds_the_one_seed_of_seed_runs():
    assert bench_delivery._args(["--maps", "warehouse"]).seeds == [0]
    assert bench_delivery._args(["--maps", "warehouse", "--seed", "3"]).seeds == [3]


@pytest.mark.parametrize("argv", [["--seeds", ""], ["--seeds", "a"], ["--seeds", "4-2"], ["--seeds", "-1"],
                                  ["--seeds", "1-"], ["--seeds", "1,,2"], ["--seeds", "1.5"],
                                  ["--seeds", "0-1", "--seed", "2"]])
def test_bad_seeds_are_an_error_naming_the_option(argv, capsys):
    with pytest.raises(SystemExit):
        bench_delivery._args(argv + ["--maps", "warehouse"])
    assert "--seeds" in capsys.readouterr().err


def _seeded() -> list[bench_delivery.Row]:
    """md and PRIOR on warehouse N=20 over seeds 0-2 (md sooner on seed 0, later on 1, tied on 2) and on
    large N=50 over seeds 0-1 (md later on both; its seed 1 run unfinished)."""
    return [
        _row("warehouse", 20, "md", seed=0, ctime=100.0, lower_bound=100.0, avg_velocity=0.5),
        _row("warehouse", 20, "prior", seed=0, ctime=110.0, lower_bound=100.0),
        _row("warehouse", 20, "md", seed=1, ctime=200.0, lower_bound=100.0, avg_velocity=0.6),
        _row("warehouse", 20, "prior", seed=1, ctime=180.0, lower_bound=90.0),
        _row("warehouse", 20, "md", seed=2, ctime=330.0, lower_bound=300.0, avg_velocity=0.7, collisions=1),
        _row("warehouse", 20, "prior", seed=2, ctime=330.0, lower_bound=300.0),
        _row("large", 50, "md", seed=0, ctime=500.0, lower_bound=250.0),
        _row("large", 50, "prior", seed=0, ctime=400.0, lower_bound=250.0),
        _row("large", 50, "md", seed=1, ctime=900.0, lower_bound=300.0, stop="stall", completed=140, deadlocks=2),
        _row("large", 50, "prior", seed=1, ctime=600.0, lower_bound=300.0),
    ]


def test_the_summary_over_seeds_counts_right():
    sums = {(s.map, s.n, s.method): s for s in bench_delivery.summarise(_seeded())}
    md = sums["warehouse", 20, "md"]
    assert md.seeds == [0, 1, 2] and md.deliveries == 60
    assert md.ctime_mean == pytest.approx(210.0) and (md.ctime_min, md.ctime_max) == (100.0, 330.0)
    assert md.ratio_mean == pytest.approx((1.0 + 2.0 + 1.1) / 3)                  # each run over its own bound
    assert (md.ratio_min, md.ratio_max) == pytest.approx((1.0, 2.0))
    assert md.v_mean == pytest.approx(0.6) and md.collisions == 1 and md.completed == 180 and md.unfinished == 0
    prior = sums["warehouse", 20, "prior"]
    assert prior.ctime_mean == pytest.approx(620 / 3) and prior.ratio_mean == pytest.approx((1.1 + 2.0 + 1.1) / 3)
    large = sums["large", 50, "md"]
    assert large.unfinished == 1 and large.completed == 290 and large.deadlocks == 2
    assert large.ratio_mean == pytest.approx(2.5) and (large.ratio_min, large.ratio_max) == pytest.approx((2.0, 3.0))

    pairs = {(c.map, c.n): c for c in bench_delivery.paired(_seeded())}
    wh, lg = pairs["warehouse", 20], pairs["large", 50]
    assert (wh.md_sooner, wh.ties, wh.seeds) == (1, 1, [0, 1, 2])         # sooner on 0, later on 1, tied on 2
    assert wh.ratio_mean == pytest.approx((100 / 110 + 200 / 180 + 1.0) / 3)
    assert (lg.md_sooner, lg.ties) == (0, 0) and lg.ratio_mean == pytest.approx((1.25 + 1.5) / 2)   # (control)

    text = bench_delivery.summary_table(_seeded())
    assert "warehouse N=20: md sooner than PRIOR on 1 of 3 seeds (1 tied); md/PRIOR CTime mean 1.007" in text
    assert "large N=50: md sooner than PRIOR on 0 of 2 seeds; md/PRIOR CTime mean 1.375" in text
    line = next(x for x in text.splitlines() if x.startswith("warehouse") and " md " in x)
    assert line.split()[3:10] == ["3", "210", "100-330", "1.37", "1.00-2.00", "0.600", "180/180"]
    assert "700!" in next(x for x in text.splitlines() if x.startswith("large") and " md " in x)   # unfinished


def test_no_paired_line_without_both_md_and_prior():
    rows = [r for r in _seeded() if r.method == "md"]
    assert bench_delivery.paired(rows) == [] and "sooner than PRIOR" not in bench_delivery.summary_table(rows)


def test_csv_keeps_the_seed_and_reads_old_csvs_as_seed_0(tmp_path):
    rows = _seeded()
    bench_delivery.write_csv(rows, tmp_path / "new.csv")
    back = bench_delivery.read_csv(tmp_path / "new.csv")
    assert back == rows and [r.seed for r in back][:6] == [0, 0, 1, 1, 2, 2]
    with (tmp_path / "new.csv").open() as f:          # a CSV of before session 29: no seed column
        lines = f.read().splitlines()
    head = lines[0].split(",")
    old = [",".join(v for k, v in zip(head, line.split(",")) if k != "seed") for line in lines]
    (tmp_path / "old.csv").write_text("\n".join(old) + "\n")
    assert "seed" not in old[0]
    assert bench_delivery.read_csv(tmp_path / "old.csv") == [replace(r, seed=0) for r in rows]


def test_multi_seed_csvs_make_a_summary_a_paper_table_of_means_and_a_plot(tmp_path, capsys):
    bench_delivery.write_csv(_seeded(), tmp_path / "rows.csv")
    png = tmp_path / "means.png"
    assert bench_delivery.main(["--paper002", "--from-csv", str(tmp_path / "rows.csv"), "--plot", str(png),
                                "--maps", "warehouse,large"]) == 1      # the seeded md run with a collision
    out = capsys.readouterr()
    assert "seed=2" in out.err and png.stat().st_size > 0
    summary = out.out[out.out.index("\nmap "):]
    assert "large N=50: md sooner than PRIOR on 0 of 2 seeds" in summary
    paper = out.out[out.out.index("\nwarehouse\n"):]
    assert "means over the seeds 0-2" in paper
    assert "   210   " in paper and "   700!   " in paper        # md's mean CTime per row (large: one unfinished)
    single = [r for r in _seeded() if r.seed == 0]                   # (control: one seed, the table as before)
    assert bench_delivery.summary_table(single) and "means over" not in bench_delivery.paper_table(single)
    assert "seed" not in bench_delivery.table(single).splitlines()[0]


def test_a_tiny_run_over_two_seeds(tmp_path, capsys):
    csv = tmp_path / "rows.csv"
    code = bench_delivery.main(["--maps", "warehouse", "--sizes", "4", "--methods", "prior",
                                "--deliveries-per-robot", "1", "--seeds", "0-1", "--csv", str(csv)])
    assert code == 0
    rows = bench_delivery.read_csv(csv)
    assert [(r.map, r.n, r.method, r.seed) for r in rows] == [("warehouse", 4, "prior", s) for s in (0, 1)]
    assert rows[0].lower_bound != rows[1].lower_bound         # each seed its own problem
    assert all(r.stop == "done" and r.completed == 4 for r in rows)
    out = capsys.readouterr().out
    mean = (rows[0].ctime + rows[1].ctime) / 2
    line = next(x for x in out.splitlines()[out.splitlines().index(""):] if x.startswith("warehouse    4 prior"))
    assert line.split()[3:5] == ["2", f"{mean:.0f}"]

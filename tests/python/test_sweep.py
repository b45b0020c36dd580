"""`ringswarm sweep` writes results.parquet that another engine reads as it is: DuckDB
finds a row per flight, the axes and the flattened summary as typed columns, and the same
numbers as the sweep's journal."""

import json
import os
import subprocess
from pathlib import Path

import duckdb
import numpy as np

from ringswarm_ref import final_velocity

ROOT = Path(__file__).resolve().parents[2]
BIN = os.environ.get("RINGSWARM_BIN", str(ROOT / "target" / "debug" / "ringswarm"))

SPEC = """
[sweep]
scenario = "paper-sim1"
seed = 5
replicates = 1

[set]
"swarm.duration_s" = 6.0

[[axis]]
key = "gains.k"
values = [1.0, 5.0]

[[axis]]
key = "gains.beta"
from = 2.0
to = 6.0
count = 3
"""


def test_duckdb_reads_a_row_per_flight_with_the_journals_numbers(tmp_path):
    spec = tmp_path / "spec.toml"
    spec.write_text(SPEC)
    out = tmp_path / "sweep"
    done = subprocess.run([BIN, "sweep", str(spec), "--out", str(out)], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    results = str(out / "results.parquet")
    con = duckdb.connect()
    types = dict((name, kind) for name, kind, *_ in con.sql(f"DESCRIBE SELECT * FROM '{results}'").fetchall())
    assert types["index"] == "BIGINT" and types["gains.k"] == "DOUBLE" and types["gains.beta"] == "DOUBLE"
    assert types["exit_code"] == "INTEGER" and types["stop_reason"] == "VARCHAR"
    assert types["timing.late_ticks"] == "BIGINT" and types["predicted_final_velocity[0]"] == "DOUBLE"
    rows = con.sql(
        f"""SELECT index, cell, "gains.k", "gains.beta", exit_code, stop_reason, formation_error_m,
                   "predicted_final_velocity[0]", "predicted_final_velocity[1]", error
            FROM '{results}' ORDER BY index"""
    ).fetchall()
    # 2 x 3 cells, one replicate: k slowest, beta 2, 4, 6 fastest.
    assert [(r[0], r[1], r[2], r[3]) for r in rows] == [
        (i, i, k, b) for i, (k, b) in enumerate((k, b) for k in (1.0, 5.0) for b in (2.0, 4.0, 6.0))
    ]
    journal = {}
    for line in (out / "flights.jsonl").read_text().splitlines():
        row = json.loads(line)
        journal[row["index"]] = row
    for r in rows:
        s = journal[r[0]]["summary"]
        assert r[4] == 0 and r[5] == "duration" and r[9] is None
        assert r[6] == s["formation_error_m"]
        assert (r[7], r[8]) == tuple(s["predicted_final_velocity"])
    # The prediction w.v0/sum(w) with paper-sim1's start velocities: it moves with k (the
    # weights do), not with beta.
    v0 = [(9.0, 4.0), (15.0, 8.0), (18.0, -2.0), (13.0, 1.0), (-8.0, -7.0), (14.0, 18.0)]
    for r in rows:
        expected = final_velocity(v0, r[2])
        assert np.allclose((r[7], r[8]), expected, rtol=0, atol=1e-12), (r, expected)
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["flights"] == 6 and manifest["axes"] == ["gains.k", "gains.beta"] and manifest["part"] == "1/1"


MAP_SPEC = """
[sweep]
scenario = "paper-sim1"
seed = 2

[set]
"swarm.duration_s" = 4.0

[[axis]]
key = "gains.k"
values = [1.0, 5.0]

[[axis]]
key = "gains.beta"
from = 0.3
to = 3.0
count = 5
scale = "log"

[[map]]
x = "gains.k"
y = "gains.beta"
metric = "exit_code"
reduce = "max"
theory = "stability"
"""


def test_a_maps_theory_boundary_is_where_numpys_closed_loop_crosses_zero(tmp_path):
    from ringswarm_ref import closed_loop_abscissa

    spec = tmp_path / "spec.toml"
    spec.write_text(MAP_SPEC)
    out = tmp_path / "sweep"
    done = subprocess.run([BIN, "sweep", str(spec), "--out", str(out)], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    assert (out / "map-exit_code.png").stat().st_size > 10_000
    assert (out / "map-exit_code.svg").read_text().startswith("<svg")
    m = json.loads((out / "map-exit_code.json").read_text())
    assert m["x"] == "gains.k" and m["y"] == "gains.beta" and len(m["ys"]) == 5
    for column in m["columns"]:
        k, beta = column["x"], column["theory_boundary"]
        # paper-sim1: six vehicles (m = 3), alpha = 1, no time scale.
        assert closed_loop_abscissa(3, k, 1.0, beta * (1 - 1e-6)) > 0, (k, beta)
        assert closed_loop_abscissa(3, k, 1.0, beta * (1 + 1e-6)) < 0, (k, beta)
        assert len(column["values"]) == 5
    # The printed lines name each k's boundary.
    assert "gains.k = 5: theory's boundary" in done.stdout

"""benchmarks/vs_peers.py reads the peers' answers right: two stand-in peers that count by brute force
over down-sets (one answering as linext, in natural logarithms; one as LEcount, an integer) agree
with opportune on every order, and a peer that is killed or fails shows no count."""

from __future__ import annotations

import json
import math
import sys

from conftest import REPO

sys.path.insert(0, str(REPO / "benchmarks"))

PEER = r'''#!{python}
import math, sys
rows = [list(map(int, line.split())) for line in open(sys.argv[1]) if line.strip()]
n = len(rows)
pred = [sum(1 << a for a in range(n) if rows[a][b]) for b in range(n)]
ways = {{0: 1}}
for size in range(n):
    nxt = {{}}
    for s, w in ways.items():
        for b in range(n):
            if not s >> b & 1 and pred[b] & s == pred[b]:
                nxt[s | 1 << b] = nxt.get(s | 1 << b, 0) + w
    ways = nxt
count = ways[(1 << n) - 1]
{answer}
'''


def fake(tmp_path, name: str, answer: str):
    path = tmp_path / name
    path.write_text(PEER.format(python=sys.executable, answer=answer))
    path.chmod(0o755)
    return str(path)


def test_the_side_by_side_table_reads_both_peers_and_agrees_with_them(tmp_path, capsys):
    import vs_peers

    # linext writes its log, the count included, to standard error
    linext = fake(tmp_path, "linext", 'print("0.01 0.01 -- LINEXT_LOG_COUNT", math.log(count), file=sys.stderr)')
    lecount = fake(tmp_path, "lecount", 'print("Counting..."); print(count)')
    assert vs_peers.main(["--linext", linext, "--lecount", lecount, "--salbp", "", "--no-generated",
                          "--sizes", "9,12", "--degrees", "2,4", "--time-limit", "5", "--json"]) == 0
    rows = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert len(rows) == 4
    for row in rows:
        assert row["opportune"]["exact"] and row["engine"]["exact"]
        assert row["linext"]["log10"] is not None and row["lecount"]["log10"] is not None
        assert row["agree"], row
        assert math.isclose(row["lecount"]["log10"], row["opportune"]["log10"], abs_tol=1e-6)
        assert row["verdict"].startswith(("ahead", "behind"))
        # CPU seconds beside wall seconds (what a shared machine compares fairly)
        for r in (row["opportune"], row["engine"], row["linext"], row["lecount"], row["armc"]):
            assert isinstance(r["cpu"], float) and r["cpu"] >= 0   # both recorded, as numbers
            assert isinstance(r["wall"], float) and r["wall"] >= 0
        assert row["opportune"]["cpu"] > 0.01          # a Python process: its start-up alone takes that
        assert row["cpu_verdict"].startswith(("engine ahead", "engine behind"))


def test_exact_counts_only_skip_the_estimates_and_the_table_says_so(tmp_path, capsys):
    import vs_peers

    linext = fake(tmp_path, "linext", 'print("0.01 0.01 -- LINEXT_LOG_COUNT", math.log(count), file=sys.stderr)')
    assert vs_peers.main(["--linext", linext, "--salbp", "", "--no-generated", "--sizes", "9", "--degrees", "2",
                          "--time-limit", "5", "--no-armc"]) == 0
    out = capsys.readouterr().out
    row = [line for line in out.splitlines() if line.startswith("| sparse")][0].split(" | ")
    assert row[6] == "skipped" and "CPU" in row[5] and row[-1].startswith("engine ")


def test_a_peer_that_fails_shows_no_count(tmp_path, capsys):
    import vs_peers

    broken = fake(tmp_path, "linext", "sys.exit(3)")
    assert vs_peers.main(["--linext", broken, "--salbp", "", "--no-generated", "--sizes", "8", "--degrees", "2",
                          "--time-limit", "5", "--json"]) == 0
    row = json.loads(capsys.readouterr().out.splitlines()[0])
    assert row["linext"]["log10"] is None and row["lecount"] is None
    assert row["verdict"] == "only opportune exact"

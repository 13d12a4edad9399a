"""The demo's data anywhere (issue 12): an installed hyst ships no data files, so away from the
repository `hyst demo` records its recordings from the twin. They must be the committed
`sample_data/` files exactly, or the demo would give other tables from another folder."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from hystcli.sim.scenarios import SAMPLE_DATA, default_data_dir, sample_data_runs
from hystcli.io import format_run, read_run

ROOT = Path(__file__).resolve().parents[1]


def test_recordings_from_the_twin_are_the_committed_sample_data_byte_for_byte():
    committed_dir = ROOT / SAMPLE_DATA
    runs = sample_data_runs()
    committed = sorted(p.relative_to(committed_dir) for p in committed_dir.rglob("*.csv")
                       if "real" not in p.relative_to(committed_dir).parts)
    assert sorted(runs) == committed and len(committed) == 22
    for rel, run in runs.items():
        on_disk = (committed_dir / rel).read_bytes()
        assert format_run(run).encode("utf-8") == on_disk, rel
        # and what the demo computes on: the same numbers as read back from the file
        back = read_run(committed_dir / rel)
        assert dict(back.meta) == dict(run.meta)
        for name in run.columns:
            assert np.array_equal(back[name], run[name]), (rel, name)


def test_the_demo_reads_sample_data_only_where_it_is(tmp_path):
    assert default_data_dir(ROOT) == ROOT / SAMPLE_DATA
    assert default_data_dir(tmp_path) is None
    # a folder named sample_data without the recordings is not taken for them
    (tmp_path / SAMPLE_DATA).mkdir()
    assert default_data_dir(tmp_path) is None

"""Run names of concurrent runs do not collide (fahv.runs.sil.reserve_run)."""

from fahv.runs.sil import reserve_run


def test_same_second_same_case_gets_distinct_names_and_folders(tmp_path):
    work, out = tmp_path / "work", tmp_path / "bags"
    (out / "case1_tube_mpc_sil_x-2").mkdir(parents=True)  # an older run in bags/
    names = [reserve_run("case1_tube_mpc_sil_x", work, out) for _ in range(3)]
    assert [n for n, _ in names] == [
        "case1_tube_mpc_sil_x",
        "case1_tube_mpc_sil_x-3",
        "case1_tube_mpc_sil_x-4",
    ]
    assert all(w.is_dir() and w.parent == work for _, w in names)

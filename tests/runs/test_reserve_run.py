"""Run names of concurrent runs do not collide (fahv.sil.runner.reserve_run), nor those of
a graph started again with one parameter file (fahv.runs.writer.free_run_folder)."""

from fahv.sil.runner import reserve_run


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


def test_a_run_folder_taken_gets_the_next_free_suffix(tmp_path):
    """The recorder started again with one parameter file: bags/<run>, then <run>-2 ..."""
    from fahv.runs.writer import RunWriter, free_run_folder

    bag = tmp_path / "bags" / "case1_tube_mpc_sil_x"
    assert free_run_folder(bag) == bag
    for expected in (bag, bag.with_name(f"{bag.name}-2"), bag.with_name(f"{bag.name}-3")):
        path = free_run_folder(bag)
        assert path == expected
        RunWriter(path, {"case": "case1"}, 0.02).close()
    assert sorted(p.name for p in bag.parent.iterdir()) == [
        "case1_tube_mpc_sil_x", "case1_tube_mpc_sil_x-2", "case1_tube_mpc_sil_x-3"
    ]  # fmt: skip

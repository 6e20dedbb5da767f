"""The condensed QP's decision vector (fahv.control.mpc.qp_layout)."""

from fahv.control.mpc.qp_layout import QPLayout


def test_qp_layout_names_the_parts_of_the_decision_vector():
    ly = QPLayout(N_p=30, m=2)
    assert ly.ny == 63 and ly.moves == slice(0, 60) and ly.move(3) == slice(6, 8)
    assert ly.delta == slice(60, 62) and ly.alpha == 62


def test_move_columns_are_the_columns_of_each_move():
    ly = QPLayout(N_p=4, m=2)
    cols = ly.move_columns
    assert cols.shape == (4, 2)
    for j in range(4):
        assert list(cols[j]) == list(range(ly.ny))[ly.move(j)]

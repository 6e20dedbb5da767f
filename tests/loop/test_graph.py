"""The node table is written once: the runner, the recorder and the docs read it."""

from pathlib import Path

from fahv.loop.graph import (
    DEFAULT_GRAPH,
    GRAPH,
    NODES,
    TOPICS,
    graph_nodes,
    markdown_table,
    replay_topics,
)

DOCS = Path(__file__).resolve().parents[2] / "docs" / "reference" / "architecture.md"


def test_docs_show_the_node_table():
    text = DOCS.read_text()
    table = text.split("<!-- node-table -->")[1].split("<!-- /node-table -->")[0]
    assert table.strip() == markdown_table().strip()


def test_graph_nodes_follow_the_table():
    assert DEFAULT_GRAPH == [
        "recorder", "state_estimator", "notch_filter", "nominal_trajectory", "tube_mpc",
        "fault_injector", "plant",
    ]  # fmt: skip
    assert graph_nodes("rmpc", record=False) == [
        "state_estimator", "notch_filter", "nominal_trajectory", "rmpc", "fault_injector", "plant"
    ]  # fmt: skip
    assert NODES["recorder"].inputs == tuple(TOPICS)
    # every loop topic has exactly one producer among the loop nodes of a run
    for topic in TOPICS:
        producers = [n for n in graph_nodes() if topic in GRAPH[n][1]]
        assert len(producers) == 1, topic
    assert replay_topics(["tube_mpc"]) == (
        ["/hsv/state_estimate", "/hsv/q_filtered", "/hsv/nominal"],
        ["/hsv/control_command", "/hsv/tube_status"],
    )


def test_docs_show_the_registry_tables():
    from fahv.loop.graph import registry_tables

    text = DOCS.read_text()
    table = text.split("<!-- registry-tables -->")[1].split("<!-- /registry-tables -->")[0]
    assert table.strip() == registry_tables().strip()

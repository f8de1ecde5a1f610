"""Commands: a node answers the actions it knows on its command key, over loopback."""

from __future__ import annotations

import pytest

from optrack.errors import UserError
from optrack.runtime.config import NODE_PARAMS
from optrack.runtime.node import CommandError, Node, send_command


class _Recorder(UserError):
    pass


def test_a_node_runs_a_command_and_returns_its_result(hub, make_client):
    node = Node(hub, "camera1", NODE_PARAMS.create(), {})
    calls: list[dict] = []

    def start(args: dict) -> dict:
        calls.append(args)
        return {"directory": f"/tmp/{args['name']}"}

    node.add_command("start_recording", start)
    client = make_client("gui")
    result = send_command(client, "camera1", "start_recording", {"name": "take1"})
    assert result == {"directory": "/tmp/take1"}
    assert calls == [{"name": "take1"}]


def test_a_refused_or_unknown_command_comes_back_as_one_sentence(hub, make_client):
    node = Node(hub, "camera1", NODE_PARAMS.create(), {})

    def refuse(args: dict) -> None:
        raise _Recorder("the disk holding /nowhere is full; free space or choose another folder.")

    node.add_command("start_recording", refuse)
    client = make_client("gui")
    with pytest.raises(CommandError, match="disk holding /nowhere is full"):
        send_command(client, "camera1", "start_recording")
    with pytest.raises(CommandError, match="has no command 'dance' \\(it has: start_recording\\)"):
        send_command(client, "camera1", "dance")
    assert "refused" in node.last_error


def test_a_command_to_a_node_that_is_not_there_says_so(hub, make_client):
    client = make_client("gui")
    with pytest.raises(CommandError, match="node 'camera9' did not answer"):
        send_command(client, "camera9", "start_recording", timeout=0.3)

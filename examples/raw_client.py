"""A reference client of the openel-async wire protocol (docs/wire.md), written with nothing
but eclipse-zenoh and msgspec -- no code of openel-async -- so that the specification, not the
implementation, is what it follows. The test suite runs it against a served rig
(tests/remote/test_raw_client.py), so docs/wire.md cannot drift from the server.

    python examples/raw_client.py tcp/127.0.0.1:7447 NAMESPACE

It lists the components, moves Motor 0 to 0.5 rad in the compact encoding and waits for that
command's ``completed`` notice, reads the position back in XML, and prints one line a step.
"""

from __future__ import annotations

import json
import sys
import threading
import uuid
from typing import Any

import msgspec
import zenoh

PROTOCOL_VERSION = 1

# -- payloads (docs/wire.md, "Payloads"): every structure is a MessagePack array ------------------


class Parameter(msgspec.Struct, array_like=True):
    data_type_id: int  # 1 int, 2 float, 3 string, 4 bool, 5 bytes, 11-14 their lists
    name: str
    value: Any


class ParameterList(msgspec.Struct, array_like=True):
    parameters: list[Parameter]


class CommandMessage(msgspec.Struct, array_like=True):
    function_name: str
    command_id: str
    arguments: ParameterList | None
    results: ParameterList | None


class Device(msgspec.Struct, array_like=True):
    device_kind: str
    commands: list[CommandMessage]


class ComponentInfo(msgspec.Struct, array_like=True):
    device_kind: str
    logical_id: int
    device_name: str
    state: str


class ComponentsReply(msgspec.Struct, array_like=True):
    protocol: int
    components: list[ComponentInfo]


class Completed(msgspec.Struct, array_like=True, tag="C"):
    command_id: str
    status: int


class Event(msgspec.Struct, array_like=True, tag="E"):
    event_id: str
    event_type: str
    subscribe_id: int
    detail: ParameterList


class Error(msgspec.Struct, array_like=True, tag="R"):
    error_id: str
    error_type: str
    detail: ParameterList


class NoticeBatch(msgspec.Struct, array_like=True):
    first_index: int
    notices: list[Completed | Event | Error]


def results_of(command: CommandMessage) -> dict[str, Any]:
    return {p.name: p.value for p in (command.results.parameters if command.results else [])}


class RawClient:
    """One client of namespace ``namespace`` on ``session``: its liveliness token, its notice
    stream, and a query per operation naming it in the attachment."""

    def __init__(self, session: zenoh.Session, namespace: str, timeout: float = 5.0) -> None:
        self.session = session
        self.root = f"openel/{namespace}"
        self.name = "raw-" + uuid.uuid4().hex[:12]  # letters, digits, '_', '.', '-'
        self.timeout = timeout
        self.completed: dict[str, int] = {}
        self.next_index = 0
        self.missed = 0
        self.changed = threading.Condition()
        self.notices = session.declare_subscriber(
            f"{self.root}/client/{self.name}/notices", self.on_notices
        )
        self.token = session.liveliness().declare_token(f"{self.root}/alive/client/{self.name}")

    def close(self) -> None:
        # (zenoh's stubs leave undeclare untyped)
        self.token.undeclare()  # type: ignore[no-untyped-call]
        self.notices.undeclare()  # type: ignore[no-untyped-call]

    def on_notices(self, sample: zenoh.Sample) -> None:
        batch = msgspec.msgpack.decode(sample.payload.to_bytes(), type=NoticeBatch)
        with self.changed:
            self.missed += max(0, batch.first_index - self.next_index)  # a gap: notices lost
            self.next_index = batch.first_index + len(batch.notices)
            for notice in batch.notices:
                if isinstance(notice, Completed):
                    self.completed[notice.command_id] = notice.status
            self.changed.notify_all()

    def query(self, key: str, payload: bytes) -> bytes:
        replies = self.session.get(
            f"{self.root}/{key}",
            payload=payload,
            attachment=self.name.encode(),
            timeout=self.timeout,
        )
        for reply in replies:
            if reply.ok is not None:
                return bytes(reply.ok.payload.to_bytes())
            raise RuntimeError(f"{key}: error reply {reply.err}")
        raise TimeoutError(f"{key}: no reply within {self.timeout} s")

    def components(self) -> ComponentsReply:
        payload = self.query("surface/components", msgspec.msgpack.encode(PROTOCOL_VERSION))
        return msgspec.msgpack.decode(payload, type=ComponentsReply)

    def execute(self, device: Device) -> Device:
        payload = self.query("surface/execute", msgspec.msgpack.encode(device))
        return msgspec.msgpack.decode(payload, type=Device)

    def execute_xml(self, xml: str) -> str:
        return self.query("surface/execute", xml.encode("utf-8")).decode("utf-8")

    def wait_completed(self, command_id: str) -> int:
        with self.changed:
            if not self.changed.wait_for(lambda: command_id in self.completed, self.timeout):
                raise TimeoutError(f"no completed notice for {command_id}")
            return self.completed[command_id]


def main(endpoint: str, namespace: str) -> int:
    config = zenoh.Config()
    config.insert_json5("mode", json.dumps("client"))
    config.insert_json5("connect/endpoints", json.dumps([endpoint]))
    config.insert_json5("scouting/multicast/enabled", "false")
    with zenoh.open(config) as session:
        client = RawClient(session, namespace)
        try:
            listing = client.components()
            print(f"protocol {listing.protocol}")
            for c in listing.components:
                print(f"component {c.device_kind}[{c.logical_id}] {c.device_name} {c.state}")
            move = Device(
                "Motor",
                [
                    CommandMessage(
                        "SetPosition",
                        "",
                        ParameterList(
                            [Parameter(1, "logical_id", 0), Parameter(2, "position", 0.5)]
                        ),
                        None,
                    )
                ],
            )
            accepted = client.execute(move).commands[0]
            code = results_of(accepted)["return_code"]
            print(f"SetPosition return_code {code} command_id {accepted.command_id}")
            status = client.wait_completed(accepted.command_id)
            print(f"completed {accepted.command_id} status {status}")
            xml = client.execute_xml(
                "<Device><device_kind>Motor</device_kind><CommandMessage>"
                "<function_name>GetPosition</function_name><command_id/><arguments>"
                "<parameters><data_type_id>1</data_type_id><name>logical_id</name>"
                "<value>0</value></parameters></arguments></CommandMessage></Device>"
            )
            start = xml.index("<name>position</name><value>") + len("<name>position</name><value>")
            print(f"GetPosition position {float(xml[start : xml.index('<', start)]):.3f}")
            print(f"notices missed {client.missed}")
        finally:
            client.close()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1], sys.argv[2]))

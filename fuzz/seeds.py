"""``python -m fuzz.seeds [DIR]``: write the seed corpus of every target into
``DIR/TARGET/`` (default ``fuzz/corpus``), from the tests' own data: the spec examples
(``tests/spec/corpus/raw``), the hostile cases' lines (``tests/lint/hostile.py``), the
built-in profiles, a story, and a conformant bag of each storage (``tests/ros/ros_bags.py``).

Generated, never committed (``fuzz/corpus`` is ignored): the script takes about a second.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests" / "lint"))

from hostile import UNIT, good_lines, heartbeat, mosquitto_j  # noqa: E402

from conformance.scenarios.story import FORMAT  # noqa: E402

SPEC = ROOT / "tests" / "spec" / "corpus" / "raw"


def _payloads() -> list[bytes]:
    """The spec's example payloads (the JSON part of each raw example)."""
    out = []
    for path in sorted(SPEC.glob("*.txt")):
        text = path.read_bytes()
        start = min((i for i in (text.find(b"{"), text.find(b"[")) if i >= 0), default=-1)
        if start >= 0:
            out.append(text[start:start + 4000])
    return out


def _formats() -> dict[str, list[bytes]]:
    """A few lines of each recording format, from the hostile corpus's good unit."""
    jsonl = good_lines(seconds=3)
    j = [mosquitto_j(len(heartbeat(1.0)), heartbeat(1.0).decode().replace('"', '\\"')),
         mosquitto_j(1, "x"), mosquitto_j(20, "x")]
    jj = [b'{"tst":"2026-11-21T07:26:55.807087Z+0100","topic":"' + UNIT.encode()
          + b'/heartbeat","qos":0,"retain":0,"payloadlen":9,"payload":' + heartbeat(1.0) + b"}",
          b"", b'{"tst":"2026-11-21T07:26:56Z+0100","topic":"a/b","qos":0,"retain":0,'
          b'"payloadlen":3,"payload":"x"}']
    v = [f"{UNIT}/heartbeat ".encode() + heartbeat(1.0), f"{UNIT}/sensor/speed 0.1".encode(),
         f"{UNIT}/sensor/camera_url (null)".encode()]
    return {"jsonl": jsonl, "j": j, "jj": jj, "v": v}


def _story() -> bytes:
    steps = [{"action": a} for a in (
        {"do": "start", "task": "move-to", "task_uuid": True, "slot": 0},
        {"do": "signal", "signal": "$pause", "slot": 0}, {"do": "query", "slot": 0},
        {"do": "resend", "step": 0}, {"do": "ping"}, {"do": "wait", "periods": 2},
        {"do": "signal", "signal": "$abort", "slot": 0, "teardown": True})]
    return json.dumps({"format": FORMAT, "unit": UNIT, "seed": 1, "steps": steps}).encode()


def seeds() -> dict[str, list[bytes]]:
    """Each target's seeds."""
    from fuzz.bags import good_bag, storage_file

    formats = _formats()
    payloads = _payloads()
    out: dict[str, list[bytes]] = {
        "recording_mixed": [b"\n".join(lines) + b"\n" for lines in formats.values()]
        + [b"\n".join(formats["jj"][:1] + formats["j"]) + b"\n",
           b"\n".join(formats["jsonl"][:4] + formats["v"]) + b"\n"],
        "validate_input": [b"\x00\x01" + p for p in payloads],
        "message_path": [b"\x04" + p[:200] for p in payloads],
        "option_parsers": [bytes([i, 0]) + s.encode() for i in range(4) for s in (
            UNIT, "waraps/#", "mqtt://127.0.0.1:1883", "10m", "1h30m")],
        "explore_replay": [_story()],
        "profile_loader": [p.read_bytes() for p in (ROOT / "profiles").glob("*.yaml")],
    }
    for name in ("recording_jsonl", "recording_mosquitto_j", "recording_mosquitto_jj",
                 "recording_mosquitto_v"):
        out[name] = [bytes(range(i, i + 64)) for i in range(0, 192, 32)]
    for storage in ("ros1", "sqlite3", "mcap"):
        out[f"rosbag_{storage}"] = [storage_file(good_bag(storage)).read_bytes()]
    out["rosbag_metadata"] = [(good_bag("sqlite3") / "metadata.yaml").read_bytes()]
    return out


def write(directory: Path) -> dict[str, Path]:
    """The seeds written into ``directory/TARGET``; returns each target's folder."""
    folders = {}
    for target, items in seeds().items():
        folder = directory / target
        folder.mkdir(parents=True, exist_ok=True)
        for i, data in enumerate(items):
            (folder / f"seed-{i:03d}").write_bytes(data)
        folders[target] = folder
    return folders


if __name__ == "__main__":
    where = Path(sys.argv[1]) if len(sys.argv) > 1 else ROOT / "fuzz" / "corpus"
    for target, folder in write(where).items():
        print(f"{target}: {len(list(folder.iterdir()))} seeds in {folder}")

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


def _compressed() -> list[bytes]:
    """A chunk's worth of a recording compressed by each of bz2, lz4 and zstd, with its
    true size declared and with none."""
    import bz2
    import struct

    import lz4.frame  # type: ignore[import-untyped]

    from conformance.baginflate import _zstd

    raw = b"\n".join(good_lines(seconds=3))
    out = []
    for i, packed in enumerate((bz2.compress(raw), lz4.frame.compress(raw),
                                _zstd().compress(raw))):
        out += [bytes([i]) + struct.pack("<I", len(raw)) + packed,
                bytes([i]) + b"\xff\xff\xff\xff" + packed]
    return out


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
    out["profile_draft"] = [b"heartbeat " + heartbeat(1.0) + b"\x00sensor/speed 0.1",
                            b"\x00".join([b"heartbeat " + heartbeat(float(i)) for i in range(4)])]
    out["environment"] = [b"127.0.0.1\x001883\x00true\x00user\x00pw",
                          b"broker.example\x00\x00off", b"127.0.0.1\x00\x00ture"]
    out["serve_address"] = [b"\x01" + s.encode() for s in ("8080", "127.1:0", "[::1]:9")]
    out["bag_inflate"] = _compressed()
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

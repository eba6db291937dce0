"""A ROS 2 bag's ``metadata.yaml`` checked before ``rosbags`` reads it.

rosbags loads the file with PyYAML whole: a billion laughs (1 KB of aliases) hangs it, and
deep nesting recurses. rosbag2 writes a few KB of plain YAML, with no anchor or alias, five
levels deep; anything else is refused here, read as a stream of YAML events (linear in the
file, nothing expanded), before rosbags sees it.
"""

from __future__ import annotations

from pathlib import Path

MAX_METADATA_BYTES = 1 << 20
"""A ROS 2 bag's metadata.yaml larger than this is refused (rosbag2 writes a few KB)."""
MAX_METADATA_DEPTH = 32
"""Nesting of metadata.yaml's mappings and lists (rosbag2 writes 5 levels)."""


def check_metadata(path: Path) -> str:
    """Refuse a metadata.yaml that rosbags' YAML loader must not be given: over
    ``MAX_METADATA_BYTES``, with anchors or aliases (a billion laughs: rosbag2 writes none), or
    nested past ``MAX_METADATA_DEPTH``: what is wrong and how to fix it, or '' for a file to
    read. Read as YAML events: linear in the file, nothing expanded."""
    import yaml

    if not path.is_file():
        return ""
    with path.open("rb") as f:
        raw = f.read(MAX_METADATA_BYTES + 1)
    why = ""
    if len(raw) > MAX_METADATA_BYTES:
        why = f"it is larger than {MAX_METADATA_BYTES >> 20} MiB"
    else:
        depth = 0
        try:
            for event in yaml.parse(raw, Loader=yaml.SafeLoader):
                if isinstance(event, yaml.AliasEvent) or getattr(event, "anchor", None):
                    why = "it uses YAML anchors or aliases (rosbag2 writes none)"
                elif isinstance(event, (yaml.MappingStartEvent, yaml.SequenceStartEvent)):
                    depth += 1
                    if depth > MAX_METADATA_DEPTH:
                        why = f"it nests deeper than {MAX_METADATA_DEPTH} levels"
                elif isinstance(event, (yaml.MappingEndEvent, yaml.SequenceEndEvent)):
                    depth -= 1
                if why:
                    break
        except yaml.YAMLError as e:
            why = f"it is not YAML ({' '.join(str(e).split())[:200]})"
    if not why:
        return ""
    return (f"{path}: not a metadata.yaml rosbag2 writes: {why}, so nothing was judged. "
            f"Fix: 'ros2 bag reindex {path.parent}', or record it again")


def odd_count(path: Path, counts: list[object]) -> str:
    """The bag's message counts (per topic, in all) as rosbags read them from its index or
    metadata.yaml ('message_count: lots' was a TypeError): what is wrong, or ''."""
    odd = [n for n in counts if n is not None and (type(n) is not int or n < 0)]
    if not odd:
        return ""
    return (f"{path}: a message count of the bag is {str(odd[0])[:40]!r}, not a whole number: "
            f"its index or metadata.yaml is damaged, so nothing was judged. Fix: reindex it "
            f"('rosbag reindex' / 'ros2 bag reindex') or record it again")

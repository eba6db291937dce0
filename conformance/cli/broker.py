"""``waraps-conformance broker``: run the embedded amqtt broker on loopback."""

from __future__ import annotations

from conformance.cli import options as opts


def main(argv: list[str]) -> int:
    parser = opts.parser("broker",
                         "Run the embedded amqtt broker on 127.0.0.1. Prints its URL first.")
    parser.add_argument("--port", type=int, default=None,
                        help="TCP port (default: a free one)")
    args = parser.parse_args(argv)
    if args.port is not None and not 0 < args.port < 65536:
        parser.error(f"--port {args.port}: a port is from 1 to 65535")
    from conformance.broker import serve

    serve(args.port)
    return 0

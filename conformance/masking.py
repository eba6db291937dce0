"""A URL or a command line made fit to print: ``mask_password``,
the one masking every printer of a URL uses (the CLI's messages, the certification's header,
summary and repeat lines, the reports' ``broker``). Paho-free: reports and lint load it."""

from __future__ import annotations

import re

_URL_START = re.compile(r"""(?<![^\s"'(<\[=,])[a-z][a-z0-9+.-]*://""", re.I)
"""Where a URL begins in text: a scheme at the start of a word (``--broker=mqtt://``,
``'mqtt://``); a ``x://`` inside a password does not begin one."""
_URL_END = re.compile(r"\n|\s(?:--?[a-z]|[a-z_][\w.-]*=)", re.I)
"""Where a URL in text ends at the latest: a line break, the next option of a command line
(`` --seed``) or the next field of a line of fields (`` units=``, sim's ready line)."""
_HOST_AFTER = re.compile(r"@(?=[^\s@])")
"""An '@' with a host after it: the user-info ends at the last one (RFC 3986 3.2.1)."""


def mask_password(text: str, *, url: bool = False, hidden: str | None = "***") -> str:
    """``text`` with the password of every ``scheme://user:password@host`` in it shown as
    ``hidden`` (None: left out with its ':', ``scheme://user@host``, a URL to paste again):
    the one place a URL or a command line is made fit to print.

    ``url``: ``text`` is one URL, or a bare ``user:password@host`` (what ``--broker`` and
    ``WARAPS_BROKER`` accept), whatever it holds. Else ``text`` is a message or a command
    line, and each URL in it runs to the next URL, line break, option (`` --x``) or field
    (`` x=``).
    A password may hold any character ('/', '#', '?', ' ', '@', ':'): the user-info runs to
    the last '@' followed by a host, and everything after the user's first ':' is hidden.
    With ``url``, what merely looks like one (``u:p@h``) is masked too: hiding too much is
    the safe mistake."""
    if "@" not in text:
        return text  # the usual case: nothing that could be a password
    if url:
        scheme = _URL_START.match(text)
        cut = scheme.end() if scheme else 0
        return text[:cut] + _masked_userinfo(text[cut:], hidden)
    out, pos = [], 0
    urls = list(_URL_START.finditer(text))
    if not urls:
        return text
    for start, following in zip(urls, [*(u.start() for u in urls[1:]), len(text)], strict=True):
        end = _URL_END.search(text, start.end(), following)  # each part of text read once
        stop = following if end is None else end.start()
        out += [text[pos:start.end()], _masked_userinfo(text[start.end():stop], hidden)]
        pos = stop
    return "".join(out) + text[pos:]


def _masked_userinfo(segment: str, hidden: str | None) -> str:
    """``segment`` (what follows a scheme) with the password of its user-info hidden."""
    ats = [m.start() for m in _HOST_AFTER.finditer(segment)] or [segment.rfind("@")]
    if ats[-1] < 0:
        return segment
    userinfo, rest = segment[:ats[-1]], segment[ats[-1]:]
    user, colon, _ = userinfo.partition(":")
    if not colon:
        return segment
    return f"{user}{rest}" if hidden is None else f"{user}:{hidden}{rest}"

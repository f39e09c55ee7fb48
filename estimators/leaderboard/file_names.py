"""File names that are safe on every shell and file system (:func:`safe_file_name`).

A scenario label or a recording's name may hold characters a shell reads as syntax (``?``,
``&``, ``=``, spaces) or a file system refuses (``/``, ``:``, ``\\`` on Windows). Every file
the leaderboard and ``duallidar run`` write is named through this one function, so its names
can be typed and globbed as they are.
"""

from __future__ import annotations

import hashlib
import re

#: Longest name returned [characters]; file systems allow 255 bytes, which leaves room for a
#: suffix and a prefix.
MAX_NAME_LENGTH = 120
_SEPARATORS = {"=": "-", "/": "_", "?": "_", "&": "_"}
_UNSAFE = re.compile(r"[^A-Za-z0-9._+-]+")


def safe_file_name(text: str) -> str:
    """``text`` as a file-name part of ASCII letters, digits, ``.``, ``_``, ``+`` and ``-``.

    ``=`` becomes ``-`` and every other run of unsafe characters one ``_`` (so
    ``closed_to_open?feature_density=0.9&feature_seed=0/zigzag/s0`` reads
    ``closed_to_open_feature_density-0.9_feature_seed-0_zigzag_s0``); a name that would start
    with ``-`` or ``.`` (an option to a shell command, a hidden file) gets a leading ``_``, an
    empty one is ``unnamed``, and one longer than :data:`MAX_NAME_LENGTH` is cut and ends in 8
    hex digits of the SHA-256 of ``text``, so different long names stay different.
    """
    name = "".join(_SEPARATORS.get(char, char) for char in text)
    name = _UNSAFE.sub("_", name)
    name = re.sub(r"_+", "_", name).strip("_")
    if not name:
        return "unnamed"
    if name[0] in "-.":
        name = "_" + name
    if len(name) > MAX_NAME_LENGTH:
        digest = hashlib.sha256(text.encode()).hexdigest()[:8]
        name = f"{name[:MAX_NAME_LENGTH - 9]}_{digest}"
    return name

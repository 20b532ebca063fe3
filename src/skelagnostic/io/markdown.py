"""Text written into Markdown reports (``summary.md``, ``evaluation.md``) that shows literally.

Clip, file, joint, dataset and method names reach the tables of the reports a
run writes. Written raw, a ``|`` splits a cell, a backtick opens code, a line
end ends the table, and ``<img src=x onerror=...>`` or ``![](http://...)`` is
HTML or an image in every viewer that renders Markdown. :func:`markdown_cell`
is the one place every table writer turns such a name into Markdown.
"""

from __future__ import annotations

import re

from skelagnostic.errors import printable

__all__ = ["markdown_cell"]

#: Markdown and HTML syntax in a name -> its escape. The backslash escapes are those both
#: Python-Markdown (MkDocs, with its tables extension) and CommonMark/GitHub understand;
#: ``<``, ``>`` and ``&`` are entities, so no tag, comment or entity is ever formed.
_ESCAPES = str.maketrans(
    {
        "\\": "\\\\",
        "`": "\\`",
        "*": "\\*",
        "[": "\\[",
        "]": "\\]",
        "|": "\\|",
        "<": "&lt;",
        ">": "&gt;",
        "&": "&amp;",
    }
)
#: An underscore that could open or close emphasis: one not between two letters or digits
#: (``mpjpe_cm`` stays as it is, ``_tmp_`` gets backslashes).
_EMPHASIS_UNDERSCORE = re.compile(r"(?<![^\W_])_|_(?![^\W_])")
#: What a backtick code span cannot hold the same way in every renderer.
_NOT_IN_CODE_SPAN = re.compile(r"[`|\\]|^\s|\s$")


def markdown_cell(value: object, *, code: bool = False) -> str:
    r"""``str(value)`` as Markdown that shows it literally, in a table cell or in a line.

    Control characters are escaped as in error messages
    (:func:`~skelagnostic.errors.printable`: a line end is shown as ``\n``);
    ``|``, backticks, backslashes, ``*``, ``[``, ``]`` and the ``_`` that could
    start or end emphasis get a backslash, and ``<``, ``>``, ``&`` become
    entities. Leading and trailing spaces of a plain cell are dropped by the
    table, as Markdown does.

    Args:
        value: The text (a name, a path, a value).
        code: Show it in code font: a backtick code span when the text holds no
            backtick, ``|`` or backslash and is not space-padded, else an HTML
            ``<code>`` element around the escaped text.

    Returns:
        One line of Markdown.

    Examples:
        >>> markdown_cell("a|b <img src=x onerror=alert(1)>")
        'a\\|b &lt;img src=x onerror=alert(1)&gt;'
        >>> markdown_cell("mpjpe_cm"), markdown_cell("_tmp_"), markdown_cell("x`|y", code=True)
        ('mpjpe_cm', '\\_tmp\\_', '<code>x\\`\\|y</code>')
        >>> markdown_cell("val/loss", code=True)
        '`val/loss`'
    """
    text = printable(value)
    if code and text and not _NOT_IN_CODE_SPAN.search(text):
        return f"`{text}`"
    escaped = _EMPHASIS_UNDERSCORE.sub(r"\\_", text.translate(_ESCAPES))
    return f"<code>{escaped}</code>" if code else escaped

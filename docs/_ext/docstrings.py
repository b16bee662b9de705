"""A griffe extension for the API reference (mkdocs.yml): the docstrings' reStructuredText markup as Markdown.

The docstrings are Google style (``Args:``, ``Returns:``) with reStructuredText roles and directives,
which Markdown would show as written (``:class:`x``` became "class:x" in a Returns entry):

- ``:class:`gegnn.Embedding``` (any role: class, meth, func, mod, data, attr, exc, obj) and
  ``:math:`(N, 3)``` become a code span, ```gegnn.Embedding```; a leading ``~`` is dropped;
- a ``.. math::`` directive line is dropped, so its indented body is shown as a code block;
- a placeholder such as ``meshes/<mesh_id>`` outside code is escaped, not swallowed as an HTML tag;
- an attribute without a docstring gets its trailing comment as one (``channels: int = 256  # width of
  every GeoConv``: the fields of ``GeGnnConfig``), or else the comment lines right above it.

Only the rendered text changes; the source files are not touched.
"""
from __future__ import annotations

import io
import re
import tokenize

import griffe

ROLE = re.compile(r":(?:py:)?(?:class|meth|func|mod|data|attr|exc|obj|math):`~?([^`]+)`")
MATH_DIRECTIVE = re.compile(r"^([ \t]*)\.\. math::[ \t]*$", re.MULTILINE)
PLACEHOLDER = re.compile(r"<([A-Za-z_][A-Za-z0-9_]*)>")
CODE_SPAN = re.compile(r"(`+).*?\1")


def _escape_placeholders(line: str) -> str:
    """``<name>`` as text, outside the line's code spans."""
    out, last = [], 0
    for span in CODE_SPAN.finditer(line):
        out += [PLACEHOLDER.sub(r"&lt;\1&gt;", line[last:span.start()]), span.group(0)]
        last = span.end()
    return "".join(out + [PLACEHOLDER.sub(r"&lt;\1&gt;", line[last:])])


def markdown(text: str) -> str:
    text = MATH_DIRECTIVE.sub(lambda m: m.group(1).rstrip(), ROLE.sub(lambda m: f"`{m.group(1)}`", text))
    lines, fenced, code, previous_blank = [], False, False, True
    for line in text.split("\n"):
        if line.lstrip().startswith(("```", "~~~")):
            fenced = not fenced
        # an indented code block starts after a blank line and runs while lines stay indented (or blank)
        blank, indented = not line.strip(), line.startswith("    ")
        code = (code and (blank or indented)) or (previous_blank and indented and not blank)
        lines.append(line if fenced or code else _escape_placeholders(line))
        previous_blank = blank
    return "\n".join(lines)


def trailing_comment(source: str) -> str | None:
    """The comment after the code of a one-line statement, if any."""
    try:
        tokens = list(tokenize.generate_tokens(io.StringIO(source).readline))
    except (tokenize.TokenError, SyntaxError):
        return None
    comments = [t.string.lstrip("#").strip() for t in tokens if t.type == tokenize.COMMENT]
    return comments[-1] if comments and comments[-1] else None


def leading_comment(obj: griffe.Object) -> str | None:
    """The block of comment lines right above a statement, joined, if any."""
    try:
        lines = obj.lines_collection[obj.filepath]
    except (KeyError, TypeError):
        return None
    block, n = [], obj.lineno - 2  # 0-based index of the line above
    while n >= 0 and lines[n].lstrip().startswith("#"):
        block.insert(0, lines[n].strip().lstrip("#").strip())
        n -= 1
    return " ".join(block) or None


class MarkdownDocstrings(griffe.Extension):
    def on_instance(self, *, obj: griffe.Object, **kwargs) -> None:
        if obj.docstring is None and obj.is_attribute and obj.lineno is not None and obj.lineno == obj.endlineno:
            comment = trailing_comment(obj.source) or leading_comment(obj)
            if comment:
                obj.docstring = griffe.Docstring(comment, lineno=obj.lineno, endlineno=obj.lineno, parent=obj)
        if obj.docstring is not None:
            obj.docstring.value = markdown(obj.docstring.value)

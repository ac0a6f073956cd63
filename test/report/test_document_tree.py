"""The format-neutral document tree: each block's Markdown and HTML, written out by hand."""

from __future__ import annotations

from pathlib import Path

from robocal_uncertainty.report.document_tree import (
    BulletList,
    Figure,
    Heading,
    Paragraph,
    Preformatted,
    render_html,
    render_markdown,
    table,
)


def test_markdown_of_every_block() -> None:
    blocks = [
        Heading(2, "Results"),
        Paragraph("u = 3 µm"),
        BulletList(("a", "b")),
        table(("x", "y"), [("1 mm", "a|b")]),
        Preformatted("col  col\n1    2"),
        Figure("f.png", "cap"),
        Figure("g.png", "alt only", caption_below=False),
    ]
    assert render_markdown(blocks) == (
        "## Results\n\nu = 3 µm\n\n- a\n- b\n\n| x | y |\n|---|---|\n| 1 mm | a\\|b |\n\n"
        "```\ncol  col\n1    2\n```\n\n![cap](f.png)\n\n*cap*\n\n![alt only](g.png)\n"
    )


def test_html_escapes_aligns_and_embeds(tmp_path: Path) -> None:
    (tmp_path / "f.png").write_bytes(b"png")  # base64 "cG5n"
    page = render_html(
        [Heading(1, "a<b"), table(("q", "v"), [("name", "1.5 mm")]), Preformatted("x < y"), Figure("f.png", "c")],
        "T&",
        tmp_path,
    )
    assert "<title>T&amp;</title>" in page
    assert "<h1>a&lt;b</h1>" in page
    # text cells left-aligned (class "text"), numbers right-aligned (the default)
    assert '<tr><td class="text">name</td><td>1.5 mm</td></tr>' in page
    assert "<pre>x &lt; y</pre>" in page and "pre{" in page  # the pre style only with a Preformatted block
    assert '<img src="data:image/png;base64,cG5n" alt="c"><figcaption>c</figcaption>' in page
    linked = render_html([Figure("f.png", "c")], "T", tmp_path, embed=False)
    assert '<img src="f.png" alt="c">' in linked and "pre{" not in linked

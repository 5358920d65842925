"""MkDocs hook: write the command reference (cli.md) from the command line's own help texts.

A page holding the line ``<!-- cli-help -->`` gets, in its place, one section per command (and
subcommand) with the text ``opportune COMMAND --help`` prints, at a fixed width of 100 columns,
so the reference cannot drift from the program.
"""

from __future__ import annotations

MARKER = "<!-- cli-help -->"
WIDTH = 100


def _sections(group, ctx, prefix: str, level: int) -> list[str]:
    import click

    out: list[str] = []
    for name in group.list_commands(ctx):
        cmd = group.get_command(ctx, name)
        if cmd is None or cmd.hidden:
            continue
        path = f"{prefix} {name}"
        with click.Context(cmd, info_name=name, parent=ctx, terminal_width=WIDTH, max_content_width=WIDTH) as sub:
            text = cmd.get_help(sub)
            out += [f"{'#' * level} `{path}`", "", "```text", text.rstrip(), "```", ""]
            if isinstance(cmd, click.Group):
                out += _sections(cmd, sub, path, level + 1)
    return out


def reference() -> str:
    """The sections of the command reference, as Markdown."""
    import click
    import typer.main

    from opportune.cli import app

    root = typer.main.get_command(app)
    settings = {**root.context_settings, "terminal_width": WIDTH, "max_content_width": WIDTH}
    with click.Context(root, info_name="opportune", **settings) as ctx:
        top = root.get_help(ctx)
        lines = ["## `opportune`", "", "```text", top.rstrip(), "```", ""]
        lines += _sections(root, ctx, "opportune", 3)
    return "\n".join(lines)


def on_page_markdown(markdown: str, page, config, files, **kwargs) -> str:
    if MARKER in markdown:
        markdown = markdown.replace(MARKER, reference())
    return markdown

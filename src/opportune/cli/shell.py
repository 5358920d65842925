"""``completion``: the shell's completion script.

The shell asks for completions by running the command with :data:`COMPLETE_VAR` set; typer's completion
classes are registered only then (:func:`opportune.cli.main`), so a normal run never pays for them
(``add_completion=True`` doubled the start-up).

Imports: typer only.
"""

from __future__ import annotations

import typer

from opportune.cli.common import fail

# The shell asks for completions by running the command with this variable set.  typer's completion classes
# are registered only then, so a normal run never pays for them (add_completion=True doubled the start-up).
COMPLETE_VAR = "_OPPORTUNE_COMPLETE"


def completion(shell: str = typer.Argument(..., help="bash, zsh, fish or powershell", show_default=False)):
    """Print the shell's completion script: add `eval "$(opportune completion bash)"` to ~/.bashrc (zsh: the
    same in ~/.zshrc; fish: `opportune completion fish > ~/.config/fish/completions/opportune.fish`)."""
    from typer.completion import get_completion_script

    shells = ("bash", "zsh", "fish", "powershell", "pwsh")
    if shell not in shells:
        fail(f"no completion for the shell '{shell}': choose {', '.join(shells[:-1])}", 2)
    print(get_completion_script(prog_name="opportune", complete_var=COMPLETE_VAR, shell=shell))

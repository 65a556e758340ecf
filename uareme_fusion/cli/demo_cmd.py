"""`uareme-fusion demo`: built-in synthetic data through the method, no files needed."""

from __future__ import annotations

from .app import app


@app.command()
def demo() -> None:
    """Run the method on built-in synthetic data and print what it gets right (about a minute)."""
    from ..demo import run_demo

    run_demo()

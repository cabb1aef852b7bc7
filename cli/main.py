"""The ``jigsaw`` command line. Heavy imports are deferred to the command that needs them."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    help="Floorplan-Jigsaw: align partial indoor scans through their room layout.",
)

PathsArg = Annotated[
    list[Path], typer.Argument(help="fragment files, or directories of *.ply / *.pcd files")
]
OutOpt = Annotated[Path | None, typer.Option("-o", "--output", help="output JSON (default stdout)")]


@app.command()
def layout(paths: PathsArg, output: OutOpt = None) -> None:
    """Estimate each fragment's local layout (walls it sees) and write them as JSON."""
    from cli.pipeline import run_layout

    raise typer.Exit(run_layout(paths, output))


@app.command()
def align(paths: PathsArg, output: OutOpt = None) -> None:
    """Align fragments into one room: poses, floorplan (result JSON of the contract)."""
    from cli.pipeline import run_align

    raise typer.Exit(run_align(paths, output))


@app.command()
def demo(
    out: Annotated[Path, typer.Option(help="folder for the scene, pictures and result")] = Path(
        "out/demo"
    ),
    seed: Annotated[int, typer.Option(help="scene seed")] = 7,
) -> None:
    """Generate a synthetic scene, run the pipeline and report errors against ground truth."""
    from cli.demo import run_demo

    raise typer.Exit(run_demo(out, seed))


@app.command()
def serve(
    host: Annotated[str, typer.Option(help="bind address")] = "127.0.0.1",
    port: Annotated[int, typer.Option(help="TCP port")] = 8000,
) -> None:
    """Run the HTTP service (embedded Redis and local workers unless FPJ_REDIS_URL is set)."""
    from api.server import run_server

    raise typer.Exit(run_server(host, port))


@app.command()
def worker(
    concurrency: Annotated[
        int | None, typer.Option(help="parallel jobs (default settings)")
    ] = None,
) -> None:
    """Run a worker process that consumes layout and placement jobs from Redis."""
    from worker.main import run_worker

    raise typer.Exit(run_worker(concurrency))


if __name__ == "__main__":
    app()

"""The ``jigsaw`` command line. Heavy imports are deferred to the command that needs them."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, TypeVar

import typer
from typer.core import TyperCommand, TyperGroup

if TYPE_CHECKING:
    from robot.client import RobotOptions


_F = TypeVar("_F", bound=Callable[..., Any])


def _plain_flags(params: list[Any]) -> list[Any]:
    """Flags show as ``--premerge`` or ``--latest/--no-latest`` in help, with no ``<bool>``."""
    for param in params:
        if getattr(param, "is_flag", False) and param.metavar is None:
            param.metavar = ""
    return params


class _Command(TyperCommand):
    def get_params(self, ctx: Any) -> list[Any]:
        return _plain_flags(super().get_params(ctx))


class _Group(TyperGroup):
    def get_params(self, ctx: Any) -> list[Any]:
        return _plain_flags(super().get_params(ctx))


app = typer.Typer(
    cls=_Group,
    add_completion=False,
    no_args_is_help=True,
    help="Floorplan-Jigsaw: align partial indoor scans through their room layout.",
)


def command(**kwargs: Any) -> Callable[[_F], _F]:
    """``app.command`` with the help layout of this CLI."""
    decorator: Callable[[_F], _F] = app.command(cls=_Command, **kwargs)
    return decorator


def _print_version(value: bool) -> None:
    if value:
        from importlib.metadata import version

        typer.echo(f"jigsaw (floorplan-jigsaw) {version('floorplan-jigsaw')}")
        raise typer.Exit()


@app.callback()
def main(
    show_version: Annotated[
        bool,
        typer.Option(
            "--version", callback=_print_version, is_eager=True, help="print the version and exit"
        ),
    ] = False,
) -> None:
    """Floorplan-Jigsaw: align partial indoor scans through their room layout."""


PathsArg = Annotated[
    list[Path],
    typer.Argument(
        help="fragments: PLY / PCD files, RGB-D frame folders (depth.png, intrinsics.json) "
        "or their zips, TUM / Redwood datasets, or directories holding these"
    ),
]
OutOpt = Annotated[Path | None, typer.Option("-o", "--output", help="output JSON (default stdout)")]


@command()
def layout(paths: PathsArg, output: OutOpt = None) -> None:
    """Estimate each fragment's local layout (walls it sees) and write them as JSON."""
    from cli.pipeline import run_layout

    raise typer.Exit(run_layout(paths, output))


@command()
def align(
    paths: PathsArg,
    output: OutOpt = None,
    cloud: Annotated[
        Path | None, typer.Option(help="also write the aligned point cloud (.ply, coloured)")
    ] = None,
    model: Annotated[
        Path | None, typer.Option(help="also write the 3D layout model (.ply or .gltf)")
    ] = None,
    picture: Annotated[
        Path | None, typer.Option(help="also write a floorplan top view (.svg or .png)")
    ] = None,
    premerge: Annotated[
        bool,
        typer.Option(
            "--premerge",
            help="first merge fragments that overlap (FPFH registration, > 60% inliers); "
            "slow (seconds per pair) and may merge wrongly on repetitive rooms",
        ),
    ] = False,
    hints: Annotated[
        Path | None,
        typer.Option(
            "--hints",
            help="hints JSON (contract section 2): prior poses with standard deviations, "
            "known neighbour pairs, known order; checked before anything runs",
        ),
    ] = None,
) -> None:
    """Align fragments into one room: poses, floorplan (result JSON of the contract).

    Exit code 0 when a result was written (whatever its status), 2 when no fragment is
    usable or an option is wrong (hints file, output path), 1 for an internal failure. A
    summary (fragments used, status, confidence, outputs) goes to stderr.
    """
    from cli.exports import ExportTargets
    from cli.pipeline import run_align

    targets = ExportTargets(cloud, model, picture)
    code = run_align(paths, output, exports=targets, premerge=premerge, hints_path=hints)
    raise typer.Exit(code)


@command()
def demo(
    out: Annotated[Path, typer.Option(help="folder for the scene, pictures and result")] = Path(
        "out/demo"
    ),
    seed: Annotated[int, typer.Option(help="scene seed")] = 7,
    service: Annotated[
        bool, typer.Option("--service", help="run it through the real service over HTTP")
    ] = False,
) -> None:
    """Generate a synthetic scene, run the pipeline and report errors against ground truth.

    With --service: start `jigsaw serve` (embedded Redis and workers), upload the fragments
    over HTTP as several robots would, wait for the loop to close, report, shut down.
    """
    if service:
        from cli.service_demo import run_service_demo

        raise typer.Exit(run_service_demo(out, seed))
    from cli.demo import run_demo

    raise typer.Exit(run_demo(out, seed))


@command()
def serve(
    host: Annotated[
        str,
        typer.Option(
            help="bind address; the default keeps HTTP on this machine until asked to open "
            "up: 0.0.0.0 (every interface) for robots on the network, with FPJ_TOKENS set"
        ),
    ] = "127.0.0.1",
    port: Annotated[int, typer.Option(help="TCP port")] = 8000,
) -> None:
    """Run the HTTP service (embedded Redis and local workers unless FPJ_REDIS_URL is set).

    Web view at http://HOST:PORT/, API docs at /docs. Set FPJ_TOKENS before opening up:
    every route but /healthz, /readyz and the web pages then needs a token with the right
    (read, upload, delete) on the route's site.
    """
    from api.server import run_server

    raise typer.Exit(run_server(host, port))


@command()
def worker(
    concurrency: Annotated[
        int | None, typer.Option(help="parallel jobs (default settings)")
    ] = None,
) -> None:
    """Run a worker process that consumes layout and placement jobs from Redis."""
    from worker.main import run_worker

    raise typer.Exit(run_worker(concurrency))


@command()
def jobs(
    retry: Annotated[
        list[str] | None,
        typer.Option("--retry", help="dead-letter entry id to queue again (repeatable)"),
    ] = None,
    retry_all: Annotated[bool, typer.Option(help="queue every dead job again")] = False,
    as_json: Annotated[bool, typer.Option("--json", help="one JSON object a line")] = False,
) -> None:
    """List the jobs given up on (the dead-letter stream) or queue them again.

    Needs FPJ_REDIS_URL (the service's Redis). Exit code 2 when Redis is not configured or
    an entry to retry does not exist.
    """
    from cli.jobs import run_jobs

    raise typer.Exit(run_jobs(retry or [], retry_all, as_json))


ConnectOpt = Annotated[
    list[str] | None,
    typer.Option("--connect", "-e", help="zenoh endpoint of the service or a router (repeatable)"),
]
SiteOpt = Annotated[str, typer.Option("--site", "-s", help="site id")]


def _robot_id(value: str) -> str:
    from schemas.ids import ID_RULE, is_valid_id

    if not is_valid_id(value):
        raise typer.BadParameter(ID_RULE)
    return value


RobotOpt = Annotated[
    str | None,
    typer.Option("--robot", parser=_robot_id, help="robot id: liveliness token and fragment tag"),
]


def _zenoh_mode(value: str) -> str:
    if value not in ("peer", "client"):
        raise typer.BadParameter("peer or client")
    return value


ModeOpt = Annotated[str, typer.Option(parser=_zenoh_mode, help="zenoh mode: peer or client")]
ScoutOpt = Annotated[bool, typer.Option("--scout", help="find the service by UDP multicast")]
PrefixOpt = Annotated[str, typer.Option(help="key expression prefix of the service")]
TokenOpt = Annotated[str | None, typer.Option(help="bearer token, if the service needs one")]
TimeoutOpt = Annotated[float, typer.Option(help="seconds to wait for the service and replies")]
TlsCaOpt = Annotated[
    Path | None,
    typer.Option("--tls-ca", help="PEM certificate of the CA that signed the service's (tls/)"),
]
TlsCertOpt = Annotated[
    Path | None,
    typer.Option("--tls-cert", help="this robot's PEM certificate, for a service with mutual TLS"),
]
TlsKeyOpt = Annotated[Path | None, typer.Option("--tls-key", help="its PEM private key")]
UserOpt = Annotated[
    str | None, typer.Option("--user", help="zenoh user name, for a service that checks one")
]
PasswordOpt = Annotated[
    str | None,
    typer.Option("--password", envvar="FPJ_ZENOH_PASSWORD", help="the user's zenoh password"),
]


@dataclass(frozen=True)
class _Credentials:
    """How a robot authenticates to a service whose zenoh peers must (README, Zenoh security)."""

    tls_ca: Path | None = None
    tls_cert: Path | None = None
    tls_key: Path | None = None
    user: str | None = None
    password: str | None = None


def _robot_options(
    connect: list[str] | None,
    mode: str,
    scout: bool,
    prefix: str,
    robot: str | None,
    token: str | None,
    timeout: float,
    credentials: _Credentials,
) -> RobotOptions:
    """The robot-side zenoh options shared by ``send`` and ``watch``."""
    from robot.client import robot_options
    from transport.config import TlsOptions

    c = credentials
    if (c.tls_cert is None) != (c.tls_key is None):
        raise typer.BadParameter("--tls-cert and --tls-key go together")
    tls = TlsOptions(c.tls_ca, c.tls_cert, c.tls_key, mtls=c.tls_cert is not None)
    return robot_options(
        connect or ["tcp/127.0.0.1:7447"],
        mode=mode,
        scout=scout,
        prefix=prefix,
        robot_id=robot,
        token=token,
        timeout=timeout,
        tls=tls if tls != TlsOptions() else None,
        user=c.user,
        password=c.password,
    )


@command()
def send(
    files: Annotated[list[Path], typer.Argument(help="PLY/PCD files; fragment id = file stem")],
    site: SiteOpt,
    connect: ConnectOpt = None,
    robot: RobotOpt = None,
    mode: ModeOpt = "peer",
    scout: ScoutOpt = False,
    prefix: PrefixOpt = "fpj",
    token: TokenOpt = None,
    timeout: TimeoutOpt = 60.0,
    tls_ca: TlsCaOpt = None,
    tls_cert: TlsCertOpt = None,
    tls_key: TlsKeyOpt = None,
    user: UserOpt = None,
    password: PasswordOpt = None,
    prior: Annotated[
        Path | None,
        typer.Option(
            "--prior",
            help='prior of the (one) fragment\'s pose, JSON {"pose", "sigma_xy", '
            '"sigma_yaw_deg"}: its entry of the site\'s hints',
        ),
    ] = None,
) -> None:
    """Send fragments to the service over zenoh (one query each); print each reply."""
    import sys

    from cli.preflight import OptionFileError, read_option_file
    from robot.client import send_fragments
    from schemas.hints import FragmentPrior

    known = None
    if prior is not None:
        if len(files) != 1:
            raise typer.BadParameter("a prior belongs to one fragment: give one file")
        try:
            known = read_option_file(prior, FragmentPrior)
        except OptionFileError as exc:
            typer.echo(exc.message, err=True)
            raise typer.Exit(2) from exc
    credentials = _Credentials(tls_ca, tls_cert, tls_key, user, password)
    options = _robot_options(connect, mode, scout, prefix, robot, token, timeout, credentials)
    raise typer.Exit(send_fragments(options, site, files, sys.stdout, sys.stderr, prior=known))


@command()
def watch(
    site: SiteOpt,
    connect: ConnectOpt = None,
    robot: RobotOpt = None,
    count: Annotated[int | None, typer.Option(help="stop after this many updates")] = None,
    duration: Annotated[float | None, typer.Option(help="stop after this many seconds")] = None,
    latest: Annotated[bool, typer.Option(help="first print the latest result's poses")] = True,
    mode: ModeOpt = "peer",
    scout: ScoutOpt = False,
    prefix: PrefixOpt = "fpj",
    token: TokenOpt = None,
    timeout: TimeoutOpt = 60.0,
    tls_ca: TlsCaOpt = None,
    tls_cert: TlsCertOpt = None,
    tls_key: TlsKeyOpt = None,
    user: UserOpt = None,
    password: PasswordOpt = None,
) -> None:
    """Print the site's pose updates over zenoh as they arrive (one JSON per line)."""
    import sys

    from robot.client import watch_poses

    credentials = _Credentials(tls_ca, tls_cert, tls_key, user, password)
    options = _robot_options(connect, mode, scout, prefix, robot, token, timeout, credentials)
    code = watch_poses(
        options, site, sys.stdout, sys.stderr, count=count, duration=duration, latest=latest
    )
    raise typer.Exit(code)


if __name__ == "__main__":
    app()

"""Connecting ``continuum-gym sweep`` to an existing Ray cluster: token authentication, a fast check of
the address, and an error that says what a cluster needs (the sweep's ``--address``)."""

from __future__ import annotations

import logging
import os
import socket
import sys
import threading
from pathlib import Path

from continuum_gym.plugins import ENV_VAR as PLUGINS_VAR

AUTH_MODE_VAR = "RAY_AUTH_MODE"
#: How long the checks before ``ray.init`` wait: a TCP connection, then one GCS handshake.
PROBE_TIMEOUT_S = 10.0


# --- Connecting to a cluster ---------------------------------------------------------------------------------
# A recent Ray's head (2.60's) started with `ray start --head` uses token authentication whenever it has a
# token (any local Ray run writes ~/.ray/auth_token). Ray's own CLI then switches a client to token mode when
# RAY_AUTH_MODE is unset and a token is available, but ray.init(address=...) does not: it retries the rejected
# handshake for 20 s and raises "Failed to connect to Ray cluster" without a word about tokens. Against an
# address where nothing listens it waits for minutes. connect() does what the CLI does, checks the address in
# seconds, and raises ClusterConnectionError saying what a cluster needs.


class ClusterConnectionError(RuntimeError):
    """The Ray cluster at an address could not be reached; the message says what a cluster needs."""


def token_source() -> str | None:
    """Where Ray would read this client's authentication token from, or None if it has none."""
    if os.environ.get("RAY_AUTH_TOKEN", "").strip():
        return "RAY_AUTH_TOKEN"
    path = os.environ.get("RAY_AUTH_TOKEN_PATH")
    if path:
        return f"RAY_AUTH_TOKEN_PATH={path}" if _non_empty(Path(path).expanduser()) else None
    default = Path.home() / ".ray" / "auth_token"
    return str(default) if _non_empty(default) else None


def has_token() -> bool:
    """Whether Ray finds a token for this client (its own loader when it has one, else ``token_source``)."""
    try:
        from ray._raylet import AuthenticationTokenLoader  # type: ignore[attr-defined]  # compiled; not in its stub

        return bool(AuthenticationTokenLoader.instance().has_token(ignore_auth_mode=True))
    except Exception:  # noqa: BLE001  (a Ray without it: the same places by hand)
        return token_source() is not None


def _non_empty(path: Path) -> bool:
    try:
        return path.is_file() and bool(path.read_text().strip())
    except OSError:
        return False


def enable_token_auth_if_available() -> bool:
    """Token mode for a client, as Ray's CLI (``ray start --address``) does: ``RAY_AUTH_MODE`` unset and a token
    available (``RAY_AUTH_TOKEN``, ``RAY_AUTH_TOKEN_PATH`` or ``~/.ray/auth_token``) -> ``RAY_AUTH_MODE=token``.

    An explicit ``RAY_AUTH_MODE`` is respected. A cluster without authentication accepts a token-mode client,
    so the switch costs nothing there. Returns whether token mode is on.
    """
    mode = os.environ.get(AUTH_MODE_VAR)
    if mode is not None:
        return mode.strip().lower() == "token"
    source = token_source()
    try:
        from ray._private.authentication import authentication_token_setup as setup

        helper = setup.maybe_enable_token_auth_if_token_available
    except (ImportError, AttributeError):  # a Ray without the helper: the same rule by hand
        helper = None
    if helper is not None:
        log = logging.getLogger(setup.__name__)
        level = log.level
        log.setLevel(logging.ERROR)  # its warning is written for a head ("set RAY_AUTH_MODE=disabled to opt out")
        try:
            enabled = bool(helper(warn_if_disabled=False))
        finally:
            log.setLevel(level)
    elif source is not None:
        os.environ[AUTH_MODE_VAR] = "token"
        try:  # Ray caches its config at import: refresh it, as Ray's helper does
            from ray._raylet import Config  # type: ignore[attr-defined]  # compiled; not in its stub

            Config.initialize("")
        except Exception:  # noqa: BLE001  (no such config in this Ray: the variable alone is what it reads)
            pass
        enabled = True
    else:
        enabled = False
    if enabled:
        print(f"continuum-gym sweep: connecting with {AUTH_MODE_VAR}=token (token from {source or 'Ray'}; "
              f"{AUTH_MODE_VAR}=disabled connects without)", file=sys.stderr)
    return enabled


def connection_message(address: str, reason: str) -> str:
    """Why the cluster at ``address`` could not be reached, and what a cluster needs."""
    import ray

    plugins = os.environ.get(PLUGINS_VAR)
    mode = (os.environ.get(AUTH_MODE_VAR) or "").strip().lower()
    token = token_source()
    if mode == "token":
        client = f"in token mode, with the token from {token}" if token else "in token mode but without a token"
    else:
        client = (f"not in token mode ({AUTH_MODE_VAR}={mode})" if mode else
                  f"not in token mode ({AUTH_MODE_VAR} unset)") + (f"; a token is available ({token})" if token else
                                                                   " and has no token")
    return (f"could not connect to the Ray cluster at {address}: {reason}. "
            "Check that its head is running and reachable from here (on the head: `ray status`). "
            f"If the cluster uses token authentication (recent Ray, {ray.__version__} here, enables it for "
            f"`ray start --head` whenever the head has a token), set {AUTH_MODE_VAR}=token and provide the "
            f"cluster's token: {_token_places()} (`ray get-auth-token` on the head prints it); this client is "
            f"{client}. Every node needs the same continuum-gym version, and your plug-in "
            f"{f'modules ({plugins}) must' if plugins else 'module (--import MODULE) must'} be importable on every "
            "node: install its package there. See 'Running on a cluster' in docs/sweeps.md")


def _token_places() -> str:
    return "the file ~/.ray/auth_token, RAY_AUTH_TOKEN=<token> or RAY_AUTH_TOKEN_PATH=<file>"


def _host_port(address: str) -> tuple[str, int] | None:
    """``host:port`` or ``ray://host:port`` -> (host, port); None for what Ray resolves itself (``auto``)."""
    rest = address.split("://", 1)[1] if "://" in address else address
    host, sep, port = rest.rstrip("/").rpartition(":")
    if not sep or not port.isdigit() or not host:
        return None
    return host.strip("[]"), int(port)


def probe(address: str, timeout: float = PROBE_TIMEOUT_S) -> str | None:
    """A reason why ``ray.init(address)`` cannot succeed, found in seconds; None if none was found.

    Ray itself waits minutes where nothing listens and 20 s for a rejected token. Only definite answers count:
    a refused or unanswered TCP connection, or the GCS rejecting this client's authentication; a GCS that does
    not answer within ``timeout`` (say, one still starting) is left to ``ray.init``.
    """
    target = _host_port(address)
    if target is None:
        return None
    try:
        socket.create_connection(target, timeout=timeout).close()
    except OSError as error:
        return f"nothing accepts connections at {target[0]}:{target[1]} ({error.strerror or error})"
    if "://" in address:  # Ray Client (ray://): no GCS handshake to try
        return None
    try:
        from ray._raylet import GcsClient  # type: ignore[attr-defined]  # compiled; not in its stub
        from ray.exceptions import AuthenticationError
    except ImportError:
        return None
    outcome = {}

    def handshake():  # the constructor fetches the cluster id: one authenticated call (it releases the GIL)
        try:
            GcsClient(address=f"{target[0]}:{target[1]}")
        except AuthenticationError as error:
            outcome["rejected"] = str(error).split(". Note:")[0]
        except Exception:  # noqa: BLE001  (anything else: let ray.init decide)
            pass

    thread = threading.Thread(target=handshake, name="ray-gcs-probe", daemon=True)
    thread.start()
    thread.join(timeout)
    if "rejected" in outcome:
        return f"the cluster rejected this client's authentication ({outcome['rejected']})"
    return None


def connect(address: str | None, runtime_env: dict | None = None) -> None:
    """``ray.init`` on a new local cluster (``address`` None) or the cluster at ``address``.

    A cluster: token mode if a token is available (``enable_token_auth_if_available``), a check of the address
    in seconds (``probe``), and ``ClusterConnectionError`` (a ``RuntimeError``) saying what a cluster needs if
    the connection fails. ``runtime_env`` reaches every trial's worker, on any node.
    """
    import ray

    try:
        from ray.exceptions import AuthenticationError
    except ImportError:  # a Ray without token authentication
        AuthenticationError = ConnectionError  # type: ignore[misc, assignment]  # noqa: N806  (the fallback class)
    remote = address not in (None, "", "local")
    if remote:
        assert address is not None  # remote: a non-empty address
        # Token mode without a token: Ray's client aborts the process at its first call, so say it here.
        if enable_token_auth_if_available() and not has_token():
            raise ClusterConnectionError(connection_message(address, f"{AUTH_MODE_VAR}=token but no token found"))
        reason = probe(address)
        if reason:
            raise ClusterConnectionError(connection_message(address, reason))
    try:
        ray.init(address=address or None, ignore_reinit_error=True, include_dashboard=False, log_to_driver=False,
                 runtime_env=runtime_env or None)
    except (ConnectionError, AuthenticationError) as error:
        if not remote:
            raise
        assert address is not None  # remote: a non-empty address
        raise ClusterConnectionError(connection_message(address, str(error).strip() or type(error).__name__)) \
            from error


__all__ = ["ClusterConnectionError", "connect", "probe", "connection_message", "enable_token_auth_if_available",
           "has_token", "token_source", "AUTH_MODE_VAR", "PROBE_TIMEOUT_S"]

"""An aiohttp application served from a thread and event loop of its own, beside blocking code.

    server = BackgroundServer("--view 127.0.0.1:8080", make_app, [("127.0.0.1", 8080, None)], serving)
    threading.Thread(target=server.run, daemon=True).start()
    server.wait_listening()    # ConfigError if a port cannot be bound
    server.ports               # the bound ports, one per site (useful with port 0)
    ...
    server.close()             # `serving` sees `closing` and returns; the server shuts down

`make_app()` builds the application on the server's loop; `serving()` is what the loop does while
the sites listen (a court view's ticks, a phone's wait for `stop`) and returns to shut the server
down; `after()` runs once the sites are closed (a phone flushes what it holds). `run` is the
thread's body: an error before the server listens is kept for `wait_listening` to raise, one after
it is raised from `run` (the thread's owner decides: the phone hands it to its consumer, the court
view logs it). Used by the phone source (edge/sources/phone/server.py) and the hub's court view
(reckon/web/court_view.py), which imports it from here: the edge never imports reckon.
"""

from __future__ import annotations

import asyncio
import ssl
import threading
from collections.abc import Awaitable, Callable, Sequence

from aiohttp import web

from protocol.errors import ConfigError

POLL_S = 0.1  # how often `wait_closing` looks at the close flag
Site = tuple[str, int, ssl.SSLContext | None]  # host, port (0: any free one), TLS context or None


class BackgroundServer:
    """See the module docstring. `where`: how the server is named in a start-up error."""

    def __init__(self, where: str, make_app: Callable[[], web.Application], sites: Sequence[Site],
                 serving: Callable[[], Awaitable[None]] | None = None,
                 after: Callable[[], Awaitable[None]] | None = None):
        self.where, self.make_app, self.sites = where, make_app, list(sites)
        self.serving = serving or self.wait_closing
        self.after = after
        self.ports: list[int] = []
        self._closing = threading.Event()
        self._listening = threading.Event()
        self._error: BaseException | None = None

    @property
    def closing(self) -> bool:
        return self._closing.is_set()

    def close(self) -> None:
        """Ask the server to stop (returns at once; join the thread to wait for it)."""
        self._closing.set()

    def wait_listening(self) -> None:
        """Block until every site listens; ConfigError naming `where` if the server could not start."""
        self._listening.wait()
        if self._error is not None:
            raise ConfigError(f"{self.where}: cannot listen ({self._error})") from self._error

    async def wait_closing(self) -> None:
        """The default `serving`: until `close()`."""
        while not self.closing:
            await asyncio.sleep(POLL_S)

    def run(self) -> None:
        """The server thread's body: serve until `serving` returns."""
        try:
            asyncio.run(self._serve())
        except BaseException as error:
            if self._listening.is_set():
                raise
            self._error = error
        finally:
            self._listening.set()  # never leave wait_listening waiting

    async def _serve(self) -> None:
        runner = web.AppRunner(self.make_app(), access_log=None, handle_signals=False)
        await runner.setup()
        try:
            for host, port, context in self.sites:
                site = web.TCPSite(runner, host, port, ssl_context=context)
                await site.start()
                self.ports.append(site._server.sockets[0].getsockname()[1])  # type: ignore[union-attr]
            self._listening.set()
            await self.serving()
        finally:
            await runner.cleanup()
        if self.after is not None:
            await self.after()

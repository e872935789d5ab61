"""Who may see and control a run through its live view: whoever holds the viewer's key, a
secret made when it starts and printed once in its URL (`http://HOST:PORT/?key=KEY`). A
request shows it as the `key` query parameter or as the cookie the first keyed visit sets
(HttpOnly, SameSite=Strict), which the page's own requests carry."""

from __future__ import annotations

import hmac
import secrets
from dataclasses import dataclass, field

KEY_PARAM = "key"


@dataclass(frozen=True)
class Access:
    """The key of the viewer listening on `port` (its cookie is named after the port: a
    browser sends a host's cookies to every port of it)."""

    port: int
    key: str = field(default_factory=lambda: secrets.token_urlsafe(32), repr=False)

    @property
    def cookie_name(self) -> str:
        """The cookie that carries the key."""
        return f"gonio_watch_{self.port}"

    def set_cookie(self) -> str:
        """The Set-Cookie header's value for a keyed visit."""
        return f"{self.cookie_name}={self.key}; HttpOnly; SameSite=Strict; Path=/"

    def matches(self, given: str) -> bool:
        """Whether a string is the key (in constant time)."""
        return hmac.compare_digest(given.encode("utf-8", "surrogateescape"), self.key.encode())

    def shown_by(self, query: dict[str, list[str]], cookie_header: str | None) -> str | None:
        """How a request shows the key: "query", "cookie", or None (it does not)."""
        if any(self.matches(v) for v in query.get(KEY_PARAM, ())):
            return "query"
        for part in (cookie_header or "").split(";"):
            name, _, value = part.strip().partition("=")
            if name == self.cookie_name and self.matches(value):
                return "cookie"
        return None

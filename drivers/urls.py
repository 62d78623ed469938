"""Device URLs (DESIGN.md): ``scheme://netloc/path?key=value``.

Kept separate from the registry so the CLI and the suit can parse and build URLs
without opening anything.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from urllib.parse import parse_qsl, quote, urlsplit


@dataclass(frozen=True)
class DeviceURL:
    scheme: str
    netloc: str
    path: str
    params: dict[str, str] = field(default_factory=dict)

    def get(self, key: str, default: str | None = None) -> str | None:
        return self.params.get(key, default)

    def get_float(self, key: str, default: float) -> float:
        v = self.params.get(key)
        try:
            return default if v is None else float(v)
        except ValueError as exc:
            raise ValueError(f"URL parameter {key}={v!r} is not a number") from exc

    def get_int(self, key: str, default: int) -> int:
        v = self.params.get(key)
        try:
            return default if v is None else int(v, 0)
        except ValueError as exc:
            raise ValueError(f"URL parameter {key}={v!r} is not an integer") from exc

    def get_bool(self, key: str, default: bool) -> bool:
        v = self.params.get(key)
        if v is None:
            return default
        return v.lower() in ("1", "true", "yes", "on")


def parse_url(url: str) -> DeviceURL:
    if "://" not in url:
        raise ValueError(f"not a device URL (expected scheme://...): {url!r}")
    u = urlsplit(url)
    return DeviceURL(u.scheme.lower(), u.netloc, u.path, dict(parse_qsl(u.query)))


def build_url(scheme: str, netloc: str = "", path: str = "", **params: object) -> str:
    q = "&".join(f"{k}={quote(str(v), safe='/:.')}" for k, v in params.items() if v is not None)
    return f"{scheme}://{netloc}{path}" + (f"?{q}" if q else "")

"""Where `facesvg live` listens: its ports and their checks (apart from the server, so that building the `facesvg`
parser does not import websockets: every command builds it)."""

from __future__ import annotations

from dataclasses import dataclass, fields

from converter.errors import InputError


@dataclass(frozen=True)
class Ports:
    """Where the bridge listens: UDP for each app, TCP for the players' WebSocket; 0 takes any free port."""

    llf: int = 11111  # Live Link Face's default target port
    ifm: int = 49983  # iFacialMocap's
    vmc: int = 39539  # the VMC protocol's (a performer's receiving port)
    ws: int = 8765

    def check(self) -> Ports:
        """The ports, or an InputError when two UDP listeners were given the same one."""
        udp = [(f.name, getattr(self, f.name)) for f in fields(self) if f.name != "ws"]
        for i, (a, pa) in enumerate(udp):
            for b, pb in udp[i + 1:]:
                if pa and pa == pb:
                    raise InputError(f"--{a}-port and --{b}-port are both {pa}; give each listener its own port.")
        return self


def port_number(text: str, flag: str) -> int:
    """A port given on the command line (0: any free one), or an InputError naming the flag."""
    try:
        port = int(str(text).strip())
    except ValueError:
        raise InputError(f"{flag} {str(text)[:20]!r} is not a port number; give one from 1 to 65535.") from None
    if not 0 <= port <= 65535:
        raise InputError(f"{flag} {port} is not a port number; give one from 1 to 65535.")
    return port

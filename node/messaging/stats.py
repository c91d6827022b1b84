from dataclasses import asdict, dataclass


@dataclass
class MessengerStats:
    sent: int = 0
    failed: int = 0
    received: int = 0
    blocked_s: float = 0.0
    blocked_max_s: float = 0.0

    def as_dict(self) -> dict:
        return asdict(self)

"""bywire's buses for python-can: ``can.Bus(interface="bywire", channel=SPEC)`` opens any bus
bywire opens (registered through python-can's ``can.interface`` entry point, so nothing but the
package needs installing)::

    import can
    with can.Bus(interface="bywire", channel="udp:") as bus:
        bus.send(can.Message(arbitration_id=0x100, data=b"\\x01\\x02", is_extended_id=False))
        print(bus.recv(1.0))

``channel`` is a bus spec: ``virtual:NAME`` and ``sim:NAME@BITRATE`` (in-process: what this
process sends there reaches bywire tools running in it, e.g. through ``bywire._native.run_cli``),
``socketcan:IFACE``, ``socketcand:HOST:PORT/BUS``, ``slcan:PORT@BITRATE``, ``udp:[GROUP[:PORT]]``
(python-can's ``udp_multicast`` group by default). Messages carry the bus's own timestamps (Unix
seconds, as python-can's are). ``can_filters`` are applied by python-can; ``send_periodic`` is
python-can's thread-based task; ``receive_own_messages=True`` returns this bus's own frames with
``is_rx=False``."""

from __future__ import annotations

from typing import Any

import can

from . import _native


class BywireBus(can.BusABC):
    """A python-can bus on any bywire bus spec."""

    def __init__(
        self,
        channel: str,
        can_filters: can.typechecking.CanFilters | None = None,
        receive_own_messages: bool = False,
        fd: bool = True,
        **kwargs: Any,
    ) -> None:
        if not isinstance(channel, str) or not channel:
            raise can.CanInitializationError("channel: a bywire bus spec such as 'udp:' or 'virtual:demo'")
        try:
            self._bus = _native.CanBus(channel, receive_own_messages)
        except (OSError, ValueError) as error:
            raise can.CanInitializationError(str(error)) from error
        self.channel = channel
        self.channel_info = f"bywire {channel}"
        self._fd = fd
        super().__init__(channel=channel, can_filters=can_filters, **kwargs)

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        if msg.is_error_frame:
            raise can.CanOperationError("an error frame cannot be sent")
        if msg.is_fd and not self._fd:
            raise can.CanOperationError("an FD frame on a bus opened with fd=False")
        try:
            self._bus.send(
                msg.arbitration_id,
                msg.is_extended_id,
                msg.is_remote_frame,
                msg.is_fd,
                msg.bitrate_switch,
                msg.error_state_indicator,
                bytes(msg.data),
                msg.dlc,
            )
        except (ValueError, OSError) as error:
            raise can.CanOperationError(str(error)) from error

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        try:
            received = self._bus.recv(timeout)
        except OSError as error:
            raise can.CanOperationError(str(error)) from error
        if received is None:
            return None, False
        timestamp, arbitration_id, extended, remote, error, fd, brs, esi, dlc, data, own = received
        message = can.Message(
            timestamp=timestamp,
            arbitration_id=arbitration_id,
            is_extended_id=extended,
            is_remote_frame=remote,
            is_error_frame=error,
            is_fd=fd,
            bitrate_switch=brs,
            error_state_indicator=esi,
            # python-can's dlc is the data's length (a remote frame's: the length asked for).
            dlc=dlc if remote else len(data),
            data=data,
            channel=self.channel,
            is_rx=not own,
            check=False,
        )
        return message, False

    def shutdown(self) -> None:
        super().shutdown()
        self._bus.shutdown()

    @staticmethod
    def _detect_available_configs() -> list[dict[str, Any]]:
        # In-process and multicast buses need no hardware to be there.
        return [{"interface": "bywire", "channel": "udp:"}]

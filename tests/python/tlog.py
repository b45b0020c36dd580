"""Reading a run directory's traffic.tlog with pymavlink."""

from pymavlink import mavutil


def read_tlog(path):
    """Every message of a .tlog (8-byte time stamp + frame each), in order."""
    log = mavutil.mavlink_connection(str(path), dialect="common")
    messages = []
    while True:
        msg = log.recv_msg()
        if msg is None:
            return messages
        messages.append(msg)

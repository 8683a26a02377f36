"""Emulated rig devices that speak the real wire protocols, for tests and rehearsals without a rig.

Each emulator serves the bytes a real device would (a Dynamixel bus, an NDI Aurora, the UDP
translation/rotation stage), so the hardware backend runs through its real SDKs against it;
faults (dropped, corrupt or late replies, device errors, silence) are switchable.
"""

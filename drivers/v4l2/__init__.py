"""V4L2 capture on our own small ctypes layer: structs, one function per ioctl, a device on top.

(The open pure-Python binding is GPL; rigctl is Apache-2.0, and the ioctls a capture path needs are few.)
"""

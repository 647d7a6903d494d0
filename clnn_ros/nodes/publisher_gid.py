"""Subscriptions that tell which publisher sent each message.

rmw gives every taken message the GID of its publisher (rmw_message_info_t.publisher_gid), but
the installed rclpy (Jazzy 7.1.6, pinned in requirements-ros.txt) hides it: the message info it
gives a two-argument callback has only timestamps and sequence numbers, and its EventsExecutor
takes messages in C++ (overriding the handle's take_message does not reach it) and fails on
two-argument callbacks ("SystemError: null argument to internal routine"). So the take is done
here: the rcl subscription is not handed to the executor; rcl_take_serialized_message (through
ctypes) keeps the message info and rclpy deserializes the bytes.

Waking the executor: when a message arrives, rmw calls the subscription's on-new-message
callback on a DDS thread. That callback is rcl_timer_reset itself (C, lock-free, thread-safe,
no Python) on a canceled zero-period timer of the node, the "doorbell": a reset timer is ready
at once, so the executor (either kind) runs its callback, which cancels it and takes every
message of every input of the node. rcl_timer_reset(timer) stands in for callback(user_data,
count): the timer is the user data, the count is ignored (a function called with one argument
more than it reads, fine in the x86-64 and AArch64 calling conventions). Under a flood of
messages (scripts/fuzz_graph.py) a ring is now and then lost: a message was seen waiting with
the doorbell canceled, which stalled the graph. So a periodic sweep (SWEEP_S) also takes
whatever is waiting; without a lost ring it finds nothing.
"""

from __future__ import annotations

import ctypes
from typing import Callable

from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.qos import QoSProfile
from rclpy.serialization import deserialize_message
from rclpy.type_support import check_is_valid_msg_type

RMW_GID_STORAGE_SIZE = 16  # rmw/types.h of Jazzy
RCL_RET_OK = 0
SWEEP_S = 0.05  # the safety net's period: what a missed doorbell may cost, at most


class _Allocator(ctypes.Structure):  # rcutils_allocator_t
    _fields_ = [("allocate", ctypes.c_void_p), ("deallocate", ctypes.c_void_p),
                ("reallocate", ctypes.c_void_p), ("zero_allocate", ctypes.c_void_p),
                ("state", ctypes.c_void_p)]


class _SerializedMessage(ctypes.Structure):  # rcl_serialized_message_t (rcutils_uint8_array_t)
    _fields_ = [("buffer", ctypes.c_void_p), ("buffer_length", ctypes.c_size_t),
                ("buffer_capacity", ctypes.c_size_t), ("allocator", _Allocator)]


class _Gid(ctypes.Structure):  # rmw_gid_t
    _fields_ = [("implementation_identifier", ctypes.c_char_p),
                ("data", ctypes.c_uint8 * RMW_GID_STORAGE_SIZE)]


class _MessageInfo(ctypes.Structure):  # rmw_message_info_t
    _fields_ = [("source_timestamp", ctypes.c_int64), ("received_timestamp", ctypes.c_int64),
                ("publication_sequence_number", ctypes.c_uint64),
                ("reception_sequence_number", ctypes.c_uint64), ("publisher_gid", _Gid),
                ("from_intra_process", ctypes.c_bool)]


# Both libraries are loaded already (by rclpy's extension): these find the loaded copies.
_rcl = ctypes.CDLL("librcl.so")
_rcl.rcl_take_serialized_message.argtypes = [
    ctypes.c_void_p, ctypes.POINTER(_SerializedMessage), ctypes.POINTER(_MessageInfo),
    ctypes.c_void_p]
_rcl.rcl_take_serialized_message.restype = ctypes.c_int32
_rcl.rcl_subscription_set_on_new_message_callback.argtypes = [
    ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p]
_rcl.rcl_subscription_set_on_new_message_callback.restype = ctypes.c_int32
_RING = ctypes.cast(_rcl.rcl_timer_reset, ctypes.c_void_p)  # the on-new-message callback
_rcutils = ctypes.CDLL("librcutils.so")
_rcutils.rcutils_get_default_allocator.restype = _Allocator
_rcutils.rcutils_uint8_array_init.argtypes = [
    ctypes.POINTER(_SerializedMessage), ctypes.c_size_t, ctypes.POINTER(_Allocator)]
_rcutils.rcutils_uint8_array_init.restype = ctypes.c_int32
_rcutils.rcutils_uint8_array_fini.argtypes = [ctypes.POINTER(_SerializedMessage)]
_rcutils.rcutils_uint8_array_fini.restype = ctypes.c_int32


class InputsWithGid:
    """The subscriptions of one node whose callbacks get the pair (message, publisher GID); the
    GID is TopicEndpointInfo.endpoint_gid of Node.get_publishers_info_by_topic, as bytes. Call
    close() before the node is destroyed (it stops the DDS threads' wake-ups)."""

    def __init__(self, node: Node):
        self.node = node
        self.subscriptions = []
        self.doorbell = node.create_timer(0.0, self.take_all)
        self.doorbell.cancel()
        self.sweep = node.create_timer(SWEEP_S, self.take_all)

    def subscribe(self, msg_type, topic: str, callback: Callable, qos: QoSProfile) -> None:
        self.subscriptions.append(_Subscription(self.node, msg_type, topic, callback, qos,
                                                self.doorbell))

    def take_all(self) -> None:
        self.doorbell.cancel()  # first: a message arriving from now on rings again
        for subscription in self.subscriptions:
            subscription.take_all()

    def close(self) -> None:
        for subscription in self.subscriptions:
            subscription.close()
        self.node.destroy_timer(self.sweep)
        self.node.destroy_timer(self.doorbell)


class _Subscription:
    """One rcl subscription, not handed to the executor: messages arriving ring the doorbell."""

    def __init__(self, node: Node, msg_type, topic: str, callback: Callable, qos: QoSProfile,
                 doorbell):
        check_is_valid_msg_type(msg_type)  # loads the type support the handle needs
        with node.handle:
            self.handle = _rclpy.Subscription(node.handle, msg_type, topic,
                                              qos.get_c_qos_profile())
        self.node, self.msg_type, self.callback = node, msg_type, callback
        # One buffer for the life of the subscription, grown by rmw as messages need it.
        self._buffer = _SerializedMessage()
        allocator = _rcutils.rcutils_get_default_allocator()
        if _rcutils.rcutils_uint8_array_init(ctypes.byref(self._buffer), 0,
                                             ctypes.byref(allocator)) != RCL_RET_OK:
            raise MemoryError("cannot allocate a serialized-message buffer")
        self._info = _MessageInfo()
        self._set_on_new_message(_RING, doorbell.handle.pointer)

    def _set_on_new_message(self, callback, user_data) -> None:
        if _rcl.rcl_subscription_set_on_new_message_callback(
                self.handle.pointer, callback, user_data) != RCL_RET_OK:
            raise RuntimeError(f"cannot set the on-new-message callback of {self.handle}")

    def take_all(self) -> None:
        while _rcl.rcl_take_serialized_message(self.handle.pointer, ctypes.byref(self._buffer),
                                               ctypes.byref(self._info), None) == RCL_RET_OK:
            data = ctypes.string_at(self._buffer.buffer, self._buffer.buffer_length)
            self.callback((deserialize_message(data, self.msg_type),
                           bytes(self._info.publisher_gid.data)))

    def close(self) -> None:
        self._set_on_new_message(None, None)
        self.handle.destroy_when_not_in_use()
        _rcutils.rcutils_uint8_array_fini(ctypes.byref(self._buffer))

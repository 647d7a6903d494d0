"""The cart-pole drawn for a 3D view (Foxglove's 3D panel, RViz): a visualization_msgs MarkerArray
of the track, the cart and the pole, in the frame `world` (x along the track, z up). Both viewers
take a frame that no TF names as their fixed frame, so no transform is published.

The drawing follows the state alone: the cart is a box centred at cart_position_m, the pole a
cylinder of twice the pole's half-length hinged on the cart's top and tilted by pole_angle_deg
about the y axis (positive leans toward +x, as in the state). The sizes of the track and the cart
are only for the eye (the model's cart is a point mass on an unbounded line)."""

from __future__ import annotations

import math
import struct

from rclpy.serialization import serialize_message
from visualization_msgs.msg import Marker, MarkerArray

FRAME = "world"
NAMESPACE = "cartpole"
# Marker ids: the same every tick, so each marker replaces its predecessor in the viewer.
TRACK, CART, POLE = 0, 1, 2
CART_SIZE_M = (0.3, 0.2, 0.15)  # x (along the track), y, z
TRACK_THICKNESS_M = 0.02
POLE_DIAMETER_M = 0.04
COLORS = {TRACK: (0.5, 0.5, 0.5), CART: (0.2, 0.4, 0.8), POLE: (0.9, 0.5, 0.1)}  # RGB


def _marker(marker_id: int, shape: int, scale: tuple[float, float, float]) -> Marker:
    marker = Marker(ns=NAMESPACE, id=marker_id, type=shape, action=Marker.ADD)
    marker.header.frame_id = FRAME
    marker.scale.x, marker.scale.y, marker.scale.z = scale
    marker.color.r, marker.color.g, marker.color.b = COLORS[marker_id]
    marker.color.a = 1.0
    marker.pose.orientation.w = 1.0
    return marker


class CartPoleMarkers:
    """One MarkerArray, refilled for each state (update), or its serialized form (serialized)."""

    def __init__(self, pole_half_length_m: float, track_limit_m: float):
        self.pole_half_length_m = pole_half_length_m
        track = _marker(TRACK, Marker.CUBE,
                        (2 * track_limit_m, CART_SIZE_M[1], TRACK_THICKNESS_M))
        track.pose.position.z = -TRACK_THICKNESS_M / 2  # the cart runs on its top face
        cart = _marker(CART, Marker.CUBE, CART_SIZE_M)
        cart.pose.position.z = CART_SIZE_M[2] / 2
        pole = _marker(POLE, Marker.CYLINDER,
                       (POLE_DIAMETER_M, POLE_DIAMETER_M, 2 * pole_half_length_m))
        self.array = MarkerArray(markers=[track, cart, pole])
        # What changes from state to state, in the order of values(): (object, attribute).
        self._fields = [*((m.header.stamp, name) for m in (track, cart, pole)
                          for name in ("sec", "nanosec")),
                        (cart.pose.position, "x"), (pole.pose.position, "x"),
                        (pole.pose.position, "z"), (pole.pose.orientation, "y"),
                        (pole.pose.orientation, "w")]
        self._template, self._offsets = self._layout()

    def values(self, stamp: tuple[int, int], cart_position_m: float,
               pole_angle_deg: float) -> tuple:
        """The numbers of one state's markers, in the order of self._fields."""
        # A cylinder's axis is its local z: turn it by the pole angle about y, centre it half
        # a pole length from the hinge along the tilted axis.
        theta = math.radians(pole_angle_deg)
        return (*stamp * 3, cart_position_m,
                cart_position_m + self.pole_half_length_m * math.sin(theta),
                CART_SIZE_M[2] + self.pole_half_length_m * math.cos(theta),
                math.sin(theta / 2), math.cos(theta / 2))

    def update(self, stamp: tuple[int, int], cart_position_m: float,
               pole_angle_deg: float) -> MarkerArray:
        """The markers of one state, stamped (sec, nanosec) with the sim time of its tick."""
        for (owner, name), value in zip(self._fields,
                                        self.values(stamp, cart_position_m, pole_angle_deg)):
            setattr(owner, name, value)
        return self.array

    def serialized(self, stamp: tuple[int, int], cart_position_m: float,
                   pole_angle_deg: float) -> bytes:
        """update()'s message as the CDR bytes a publisher sends (publish takes bytes as they
        are). rclpy's serialization of a MarkerArray costs about 45 us here, more than all
        other messages of a tick together: these are its bytes laid out once, with each state's
        numbers written in (2 us)."""
        data = bytearray(self._template)
        for (offset, form), value in zip(self._offsets,
                                         self.values(stamp, cart_position_m, pole_angle_deg)):
            struct.pack_into(form, data, offset, value)
        return bytes(data)

    def _layout(self) -> tuple[bytes, list[tuple[int, str]]]:
        """(the serialized markers, where each changing number lies in it and its struct
        format), found by serializing distinct marks in their places."""
        forms = {"sec": "<i", "nanosec": "<I"}  # builtin_interfaces/Time: int32, uint32
        marks = [(900_000_001 + k, forms[name]) if name in forms else (1234.5 + k / 8, "<d")
                 for k, (_, name) in enumerate(self._fields)]
        for (owner, name), (mark, _) in zip(self._fields, marks):
            setattr(owner, name, mark)
        template = serialize_message(self.array)
        offsets = []
        for mark, form in marks:
            packed = struct.pack(form, mark)
            offset = template.find(packed)
            if offset < 0 or template.find(packed, offset + 1) >= 0:
                raise RuntimeError(f"markers: {mark} is not once in the serialized markers")
            offsets.append((offset, form))
        return template, offsets

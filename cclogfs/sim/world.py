"""A small office building as a waypoint graph, and A* search over it.

The building is a grid of 2 m wide corridors with rooms off them. Nodes are corridor
crossings, door junctions on the corridors, doorways and room interiors; edges are
straight segments the robot can drive. Goals are random points inside rooms or on
corridors, so no two trips are quite alike.
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass, field

import numpy as np

__all__ = ["Building", "build_building"]

# Corridor lines (metres): three east-west corridors and five north-south ones.
_CORRIDOR_Y = (0.0, 12.0, 24.0)
_CORRIDOR_X = (0.0, 10.0, 20.0, 30.0, 40.0)
_ROOM_DEPTH = 4.0  # door junction -> room centre
_ROOM_HALF = 1.6  # goals land within this of the room centre


@dataclass
class Building:
    """Nodes (x, y), adjacency lists, and which nodes are rooms."""

    xy: np.ndarray
    adjacent: list[list[int]]
    rooms: list[int] = field(default_factory=list)
    corridor_nodes: list[int] = field(default_factory=list)

    def nearest(self, x: float, y: float) -> int:
        """Index of the node closest to (x, y)."""
        d = (self.xy[:, 0] - x) ** 2 + (self.xy[:, 1] - y) ** 2
        return int(np.argmin(d))

    def astar(self, start: int, goal: int) -> list[int]:
        """Shortest node path from start to goal (inclusive); the graph is connected."""
        xy = self.xy
        gx, gy = xy[goal]

        def h(n: int) -> float:
            return math.hypot(xy[n, 0] - gx, xy[n, 1] - gy)

        best = {start: 0.0}
        came: dict[int, int] = {}
        frontier = [(h(start), 0.0, start)]
        while frontier:
            _, cost, node = heapq.heappop(frontier)
            if node == goal:
                path = [node]
                while node in came:
                    node = came[node]
                    path.append(node)
                return path[::-1]
            if cost > best.get(node, math.inf):
                continue
            for nxt in self.adjacent[node]:
                c = cost + math.hypot(xy[nxt, 0] - xy[node, 0], xy[nxt, 1] - xy[node, 1])
                if c < best.get(nxt, math.inf):
                    best[nxt] = c
                    came[nxt] = node
                    heapq.heappush(frontier, (c + h(nxt), c, nxt))
        raise AssertionError(f"waypoint graph is disconnected between nodes {start} and {goal}")

    def random_goal(self, rng: np.random.Generator) -> tuple[int, float, float]:
        """A goal node and a point near it: mostly rooms, sometimes a corridor spot."""
        if rng.random() < 0.8:
            node = int(rng.choice(self.rooms))
            off = rng.uniform(-_ROOM_HALF, _ROOM_HALF, 2)
        else:
            node = int(rng.choice(self.corridor_nodes))
            off = rng.uniform(-0.4, 0.4, 2)
        return node, float(self.xy[node, 0] + off[0]), float(self.xy[node, 1] + off[1])


def build_building() -> Building:
    """The fixed floor plan used by every run (the seed only picks goals)."""
    nodes: dict[tuple[float, float], int] = {}
    xy: list[tuple[float, float]] = []
    edges: set[tuple[int, int]] = set()

    def node(p: tuple[float, float]) -> int:
        if p not in nodes:
            nodes[p] = len(xy)
            xy.append(p)
        return nodes[p]

    # Door junctions split corridors at 5 m; rooms hang off every east-west junction
    # (alternately north and south) that is not a crossing.
    corridor_points: dict[str, list[tuple[float, float]]] = {}
    for y in _CORRIDOR_Y:
        xs = np.arange(_CORRIDOR_X[0], _CORRIDOR_X[-1] + 0.1, 5.0)
        corridor_points[f"y{y}"] = [(float(x), y) for x in xs]
    for x in _CORRIDOR_X:
        ys = np.arange(_CORRIDOR_Y[0], _CORRIDOR_Y[-1] + 0.1, 6.0)
        corridor_points[f"x{x}"] = [(x, float(y)) for y in ys]
    for line in corridor_points.values():
        ids = [node(p) for p in line]
        for a, b in zip(ids, ids[1:]):
            edges.add((min(a, b), max(a, b)))
    corridor = list(range(len(xy)))
    rooms = []
    for y in _CORRIDOR_Y:
        for i, (px, py) in enumerate(corridor_points[f"y{y}"]):
            if px in _CORRIDOR_X:
                continue
            side = 1.0 if (i // 2) % 2 == 0 else -1.0
            if (y == _CORRIDOR_Y[0] and side < 0) or (y == _CORRIDOR_Y[-1] and side > 0):
                side = -side
            # doorway one metre in, then the room centre beyond it
            door = node((px, py + side * 1.2))
            room = node((px, py + side * _ROOM_DEPTH))
            junction = nodes[(px, py)]
            edges.add((min(junction, door), max(junction, door)))
            edges.add((min(door, room), max(door, room)))
            rooms.append(room)
    adjacent: list[list[int]] = [[] for _ in xy]
    for a, b in sorted(edges):
        adjacent[a].append(b)
        adjacent[b].append(a)
    return Building(np.array(xy, dtype=float), adjacent, rooms, corridor)

"""ROS 2's simulation_interfaces services and action on the bridge: the standard's types, the meaning in
:mod:`robotatfactory.sim.standard`. This file only wires names to calls and converts messages.

Served (ROS 2 only; names relative to the bridge's namespace; docs/ros2.md has the table per simulator):
``get_simulator_features``, ``reset_simulation``, ``get_simulation_state``, ``set_simulation_state``,
``step_simulation``, the ``simulate_steps`` action, ``get_entities``, ``get_entities_states``,
``get_entity_state``, ``set_entity_state``, ``get_entity_info``, ``get_entity_bounds``, ``spawn_entity``,
``spawn_entities``, ``get_spawnables``, ``delete_entity``, ``get_named_poses``, ``get_named_pose_bounds``.
"""
from __future__ import annotations

from ..sim import standard as st
from .messages import stamp_s

SERVICE_NAMES = {  # service name -> the standard's type name
    "get_simulator_features": "GetSimulatorFeatures", "reset_simulation": "ResetSimulation",
    "get_simulation_state": "GetSimulationState", "set_simulation_state": "SetSimulationState",
    "step_simulation": "StepSimulation", "get_entities": "GetEntities", "get_entities_states": "GetEntitiesStates",
    "get_entity_state": "GetEntityState", "set_entity_state": "SetEntityState", "get_entity_info": "GetEntityInfo",
    "spawn_entity": "SpawnEntity", "delete_entity": "DeleteEntity", "get_named_poses": "GetNamedPoses",
    "get_entity_bounds": "GetEntityBounds", "get_named_pose_bounds": "GetNamedPoseBounds",
    "get_spawnables": "GetSpawnables", "spawn_entities": "SpawnEntities",
}
ACTION_NAME = "simulate_steps"


class StandardServices:
    """The standard's services of one bridge over ``standard`` (a :class:`~robotatfactory.sim.standard.
    SimulationStandard`); ``types`` is the middleware's ``standard_sim_types()``."""

    def __init__(self, node, standard: st.SimulationStandard, types):
        self.node, self.std, self.t = node, standard, types
        self.handles: list = []

    def start(self) -> "StandardServices":
        srv = self.t.srv
        for name, typ in SERVICE_NAMES.items():
            self.handles.append(self.node.service(name, getattr(srv, typ), getattr(self, f"_{name}")))
        self.handles.append(self.node.action_server(ACTION_NAME, self.t.action.SimulateSteps, self._simulate_steps))
        return self

    def shutdown(self) -> None:
        for h in self.handles:
            self.node.close(h)
        self.handles.clear()

    # -- conversions -------------------------------------------------------------------------------------------
    def _result(self, resp, a: st.Answer):
        resp.result.result, resp.result.error_message = int(a.result), a.message
        return resp

    def _state_msg(self, e: st.Entity):
        m = self.t.msg.EntityState()
        s = e.state
        m.header.frame_id = self.std.map_frame
        m.header.stamp = stamp_s(s.time)
        m.pose.position.x, m.pose.position.y, m.pose.position.z = s.x, s.y, s.z
        _set_yaw(m.pose, s.yaw)
        m.twist.linear.x, m.twist.linear.y, m.twist.angular.z = s.vx, s.vy, s.wz
        return m

    def _box(self, box):
        """A box (x0, x1, y0, y1, z0, z1) as the standard's Bounds: TYPE_BOX, two opposite corners."""
        from geometry_msgs.msg import Vector3

        x0, x1, y0, y1, z0, z1 = (float(v) for v in box)
        return self.t.msg.Bounds(type=st.BOUNDS_BOX, points=[Vector3(x=x0, y=y0, z=z0), Vector3(x=x1, y=y1, z=z1)])

    @staticmethod
    def _quat(o) -> tuple:
        return o.x, o.y, o.z, o.w

    # -- services ----------------------------------------------------------------------------------------------
    def _get_simulator_features(self, req, resp):
        features, formats, info = self.std.features()
        resp.features.features, resp.features.spawn_formats = list(features), list(formats)
        resp.features.custom_info = info
        return resp

    def _reset_simulation(self, req, resp):
        return self._result(resp, self.std.reset(int(req.scope)))

    def _get_simulation_state(self, req, resp):
        a = self.std.simulation_state()
        if a.ok:
            resp.state.state = a.data
        return self._result(resp, a)

    def _set_simulation_state(self, req, resp):
        return self._result(resp, self.std.set_simulation_state(int(req.state.state)))

    def _step_simulation(self, req, resp):
        return self._result(resp, self.std.step(int(req.steps)))

    def _filtered(self, req):
        f = req.filters
        return self.std.filtered(f.filter, [c.category for c in f.categories], list(f.tags.tags),
                                 int(f.tags.filter_mode), int(f.bounds.type),
                                 [(p.x, p.y, p.z) for p in f.bounds.points])

    def _get_entities(self, req, resp):
        a = self._filtered(req)
        if a.ok:
            resp.entities = [e.name for e in a.data]
        return self._result(resp, a)

    def _get_entities_states(self, req, resp):
        a = self._filtered(req)
        if a.ok:
            resp.entities = [e.name for e in a.data]
            resp.states = [self._state_msg(e) for e in a.data]
        return self._result(resp, a)

    def _get_entity_state(self, req, resp):
        a = self.std.entity_state(req.entity)
        if a.ok:
            resp.state = self._state_msg(a.data)
        return self._result(resp, a)

    def _set_entity_state(self, req, resp):
        s = req.state
        twist = (s.twist.linear.x, s.twist.linear.y, s.twist.linear.z, s.twist.angular.x, s.twist.angular.y,
                 s.twist.angular.z)
        return self._result(resp, self.std.set_entity_state(req.entity, s.header.frame_id, s.pose.position.x,
                                                            s.pose.position.y, self._quat(s.pose.orientation),
                                                            twist))

    def _get_entity_info(self, req, resp):
        a = self.std.entity_info(req.entity)
        if a.ok:
            e = a.data
            resp.info.category.category = e.category
            resp.info.description, resp.info.tags = e.description, list(e.tags)
        return self._result(resp, a)

    def _spawn_request(self, name, allow_renaming, uri, resource_string, namespace, initial_pose) -> dict:
        p = initial_pose
        return dict(name=name, allow_renaming=bool(allow_renaming), uri=uri, resource_string=resource_string,
                    namespace=namespace, frame=p.header.frame_id, x=p.pose.position.x, y=p.pose.position.y,
                    q=self._quat(p.pose.orientation))

    def _spawn_entity(self, req, resp):
        a = self.std.spawn(**self._spawn_request(req.name, req.allow_renaming, req.uri, req.resource_string,
                                                 req.entity_namespace, req.initial_pose))
        if a.ok:
            resp.entity_name = a.data
        return self._result(resp, a)

    def _spawn_entities(self, req, resp):
        a = self.std.spawn_many([self._spawn_request(r.name, r.allow_renaming, r.entity_resource.uri,
                                                     r.entity_resource.resource_string, r.entity_namespace,
                                                     r.initial_pose) for r in req.spawn_requests])
        for one in a.data or []:
            out = self.t.msg.SpawnResult(entity_name=one.data if one.ok else "")
            out.result.result, out.result.error_message = int(one.result), one.message
            resp.results.append(out)
        return self._result(resp, a)

    def _get_entity_bounds(self, req, resp):
        a = self.std.entity_bounds(req.entity)
        if a.ok:
            resp.bounds = self._box(a.data)
        return self._result(resp, a)

    def _get_named_pose_bounds(self, req, resp):
        a = self.std.named_pose_bounds(req.name)
        if a.ok:
            resp.bounds = self._box(a.data)
        return self._result(resp, a)

    def _get_spawnables(self, req, resp):
        a = self.std.spawnables(list(req.sources))
        if a.ok:
            resp.spawnables = [self.t.msg.Spawnable(uri=uri, description=d, spawn_bounds=self._box(box))
                               for uri, d, box in a.data]
        return self._result(resp, a)

    def _delete_entity(self, req, resp):
        return self._result(resp, self.std.delete(req.entity))

    def _get_named_poses(self, req, resp):
        a = self.std.named_poses(list(req.tags.tags), int(req.tags.filter_mode))
        if a.ok:
            for name, description, tags, x, y, yaw in a.data:
                m = self.t.msg.NamedPose(name=name, description=description, tags=list(tags))
                m.pose.position.x, m.pose.position.y = x, y
                _set_yaw(m.pose, yaw)
                resp.poses.append(m)
        return self._result(resp, a)

    # -- the action --------------------------------------------------------------------------------------------
    def _simulate_steps(self, goal, publish_feedback, cancel_requested):
        """One control cycle per step, feedback after each; a cancel ends it between two steps."""
        A = self.t.action.SimulateSteps
        result = A.Result()
        n = int(goal.steps)
        first = self.std.require(st.STEP_SIMULATION_ACTION) or (
            st.fail(st.OPERATION_FAILED, f"steps = {n}: step at least one control cycle (40 ms)") if n < 1
            else self.std.step(1))
        if not first.ok:
            self._result(result, first)
            return "aborted", result
        done = 1
        publish_feedback(A.Feedback(completed_steps=done, remaining_steps=n - done))
        while done < n:
            if cancel_requested():
                self._result(result, st.fail(st.OPERATION_FAILED, f"canceled after {done} of {n} steps"))
                return "canceled", result
            a = self.std.step(1)
            if not a.ok:
                self._result(result, st.fail(a.result, f"step {done + 1} of {n}: {a.message}"))
                return "aborted", result
            done += 1
            publish_feedback(A.Feedback(completed_steps=done, remaining_steps=n - done))
        self._result(result, st.Answer(st.OK))
        return "succeeded", result


def _set_yaw(pose, yaw: float) -> None:
    """A geometry_msgs Pose's orientation: a rotation of ``yaw`` about z."""
    o = pose.orientation
    o.x, o.y, o.z, o.w = st.quaternion_of_yaw(yaw)

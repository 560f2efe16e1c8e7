"""JSON text conventions that ingest and export share: the well-formedness check
(`check`), the JSON Lines line format (`lines`) and ROS messages as rosbridge JSON
(`ros`, which needs numpy: import it directly)."""

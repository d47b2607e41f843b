"""Offline review of a flight: metrics (``metrics``), the flight read back from a bag
(``flight_from_bag``), plots (``plots``), the report (``report``) and the ``review`` command
(``command``; also ``python3 -m quad_msgs_bridge.review BAG``)."""

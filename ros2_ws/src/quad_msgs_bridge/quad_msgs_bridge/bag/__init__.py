"""rosbag2-compatible MCAP bags: writing (``writer``, ``flight_bag``, ``recorder_node``), reading
(``reader``), metadata (``metadata``), recovery of a killed recording (``recover``) and message
timing (``timing``). The MCAP container itself is in ``mcap_file``."""

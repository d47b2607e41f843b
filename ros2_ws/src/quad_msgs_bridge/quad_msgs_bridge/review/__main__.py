"""``python3 -m quad_msgs_bridge.review BAG ...``: the review command."""
import sys

from quad_msgs_bridge.review.command import main

sys.exit(main())

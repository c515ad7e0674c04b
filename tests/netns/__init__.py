"""Scripts the test suite runs inside a private network namespace (see tests/netns_util.py).

The sessions whose checks do not read the run's ``recording.rrd`` start ``tuav-sitl up``
with ``--no-recording``: its live recorder (a fifth process, ``tuav_sitl.view.live``) is
about a fifth of a stack's CPU. ``up``'s default, the recorder running, is what the first
minutes of a user (test_first_contact, test_cold_start), up's supervision (test_up), the
full disk (test_disk_full) and the live view (test_view_live) fly."""

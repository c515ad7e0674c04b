"""Scripts the test suite runs inside a private network namespace (see tests/netns_util.py).

The sessions whose checks do not read the run's ``recording.rrd`` start ``tuav-sitl up``
with ``--no-recording``: its live recorder (a fifth process, ``tuav_sitl.view.live``) is
about a fifth of a stack's CPU. ``up``'s default, the recorder running, is what the first
minutes of a user (test_first_contact, test_cold_start), up's supervision (test_up), the
full disk (test_disk_full) and the live view (test_view_live) fly; and so does the
GNSS-denied mission (denied_mission_session): without the recorder it failed 2 of 4
flights on an EKF failsafe (the tether fix lost), with it 5 of 5 passed, a timing
sensitivity of the tether-fix flight still to be found (issue 33)."""

"""The soak of a running liver_sim_node (scripts/soak.py): load.py sends the load, receive.py and
watch.py receive and watch, session.py runs them and keeps the run's record (record.py), judge.py
judges a record (pure functions), report.py lays the verdicts out."""

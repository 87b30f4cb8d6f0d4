"""What a run learned, measured: named policies and the reference policy
(:mod:`.policies`, :mod:`.sources`, :mod:`.baselines`), evaluation, statistics
(:mod:`.stats`) and figures."""

"""Many runs at once: sweeps (on Ray or one after another) and the reproduction report
(:mod:`.report`)."""

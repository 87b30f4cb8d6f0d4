"""The bottom of the package: the errors every layer raises for a user's mistake
(:mod:`.errors`), the commands' exit statuses (:mod:`.exitcodes`) and the versions a run
records (:mod:`.versions`). It imports nothing of the package."""

"""Prefect tasks: thin wrappers around sim2radar functions (cache policy, retries, artifact I/O). No science here."""

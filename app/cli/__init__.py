"""The `radiance-probes` command and its `animate` subcommand."""

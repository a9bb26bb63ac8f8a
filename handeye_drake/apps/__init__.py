"""Command-line applications (subcommands of ``handeye-drake``)."""

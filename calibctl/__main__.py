from calibctl.cli.main import run

run()

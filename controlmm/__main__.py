from controlmm.cli.main import entry

entry()

from endocal.cli import run

run()

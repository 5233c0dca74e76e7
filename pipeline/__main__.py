from imupipe.cli import console

console()

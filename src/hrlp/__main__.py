from hrlp.cli import main

main()

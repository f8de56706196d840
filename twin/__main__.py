from twin.cli import console_main

console_main()

from seqrun.entry import main

main()

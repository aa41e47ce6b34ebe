/* A shared object that is not a control program: it has no main. */
int not_main(void) { return 7; }

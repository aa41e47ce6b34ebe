/* A shared object without a main: loading it as a program must fail. */
int chm_test_not_main(void) { return 42; }

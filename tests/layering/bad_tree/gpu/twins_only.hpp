// A planted offence: a module header that only a test includes (test code in a product library).
#pragma once
